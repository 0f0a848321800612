// chain_file.hpp — a chain recording for `mocap-filter --chain`: a CHAIN.toml that names one
// CSV per segment and the joints between them (docs/fusion.md, "Chain recordings").
//
//   [[segment]]
//   name = "upper_arm"          # [A-Za-z0-9_-]+, unique; the output is DIR/<name>.csv
//   csv = "upper_arm.csv"       # relative to the TOML's folder; the mocap-filter --in layout
//   [[joint]]
//   parent = "upper_arm"
//   child = "forearm"
//   type = "hinge"              # hinge | 2dof | ball
//   axis_parent = [1, 0, 0]     # parent's sensor frame; with axis_child, or both omitted /
//   axis_child = [1, 0, 0]      # "estimate": learned from the motion
//   axis_angle_deg = 90         # 2dof only: the constant angle between its axes (default 90)
//
// Every segment's CSV must have the same instants (rows at the same t within a quarter of
// the sample period): a chain is recorded by one system. The files are untrusted input:
// every problem comes back as a message naming the file and what is wrong, never thrown.
// Thread-safety: pure functions. Cost: reads every file once.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "filter_tool/recording_csv.hpp"
#include "fusion/chain_estimator.hpp"

namespace mocap::tools {

struct ChainSegment {
    std::string name;
    std::string csv_path;  ///< resolved against the TOML's folder
    Recording recording;
};

struct ChainJoint {
    std::string parent, child;
    fusion::JointDef def;  ///< indices into ChainRecording::segments
};

struct ChainRecording {
    std::vector<ChainSegment> segments;
    std::vector<ChainJoint> joints;
};

/// Parses the TOML (and no CSV). nullopt + *error on any problem.
std::optional<ChainRecording> parse_chain_toml(const std::string& toml_path, std::string* error);

/// Parses the TOML and reads every segment's CSV, checking that their instants match.
std::optional<ChainRecording> load_chain(const std::string& toml_path, std::string* error);

}  // namespace mocap::tools
