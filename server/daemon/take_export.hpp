// take_export.hpp — a take's download as BVH or joint-angle CSV: the take's raw file re-solved
// by `mocapd --replay`'s code (daemon/replay.hpp) with the daemon's config, the calibrations
// the take carries, and optionally another filter (docs/client-protocol.md, "Takes").
//
// The export is written into a memfd (memfd_create: memory, never record_dir's disk, which a
// running take needs), returned open and positioned at its start; it is freed when the
// download closes it. While it is written, a request with `reserve` is told the memfd's size
// every kReplayProgressSamples samples, and an export it refuses stops there with kTooLarge
// and its reason (the web endpoint's export budget). The take's calibration files are copied
// into a hidden directory of the take store (<root>/.export-<n>, removed when the export
// ends, or at the next export after a crash), so a re-solve never writes into the take.
// Refused before anything runs: a BVH of a subject the take does not hold (kNotFound, as is
// a BVH that ends up without a frame of the requested subject), and an offline re-solve whose
// memory estimate (offline_export_estimate_bytes) exceeds [outputs] offline_export_max_mb
// (kTooLarge). After every export malloc_trim(0) gives its freed buffers back to the system.
// A requested filter replaces [filter] and every per-segment override, with that filter's
// default parameters.
//
// Threads: any (the web endpoint's export queue); one call at a time per store root is not
// required. Cost: a whole replay, ~90x real time with the default filter; checks `cancel`
// per sample.
#pragma once

#include <atomic>
#include <cstdint>

#include "daemon/config.hpp"
#include "serve/take_export_queue.hpp"
#include "serve/take_store.hpp"

namespace mocap::daemon {

/// What an offline re-solve of a take with `raw_bytes` of raw file holds at its peak, beyond
/// what the daemon holds anyway (measured, docs/reliability.md "Export memory").
inline constexpr std::uint64_t kOfflineBytesPerRawByte = 5;
std::uint64_t offline_export_estimate_bytes(std::uint64_t raw_bytes);

serve::TakeExportResult export_take(const DaemonConfig& config, const serve::TakeStore& store,
                                    const serve::TakeExportRequest& request, const std::atomic<bool>& cancel);

}  // namespace mocap::daemon
