// pipeline_config.hpp — the pipeline and its outputs, as the config file describes them:
// one translation from DaemonConfig for the daemon and for replay.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "cluster/cluster_config.hpp"
#include "daemon/config.hpp"
#include "pipeline/pipeline.hpp"
#include "serve/bvh_frame_encoder.hpp"
#include "skeleton/body_model.hpp"

namespace mocap::daemon {

/// Builds the body model from the config (the built-in body when no segment is listed).
/// Returns std::nullopt and sets *error if the model is invalid.
std::optional<skeleton::BodyModel> body_model_from_config(const DaemonConfig& config, std::string* error);

/// Subject ids, ascending: the sinks' subject_id_base + 1..subject_id_base + max_subjects
/// and every SocketCAN subject (--check-config refuses one inside the sinks' range).
std::vector<std::uint32_t> subject_ids_from_config(const DaemonConfig& config);

/// BVH unit, rotation order and frame time from [outputs].
serve::BvhOutputOptions bvh_options_from_config(const DaemonConfig& config);

/// Skeleton solver options from [skeleton] (max_subjects follows the subjects).
skeleton::PoseSolverOptions pose_solver_options_from_config(const DaemonConfig& config);

/// How to reach the cluster from [cluster]: URL, site, host id, credentials, TLS, queues and
/// raw_replicas (the cluster publisher and `--replay --jetstream` connect alike).
cluster::ClusterConfig cluster_config_from_config(const DaemonConfig& config);

/// Everything the pipeline needs; std::nullopt + *error for an invalid body model.
std::optional<pipeline::PipelineConfig> pipeline_config_from_config(const DaemonConfig& config, std::string* error);

}  // namespace mocap::daemon
