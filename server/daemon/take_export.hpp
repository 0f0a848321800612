// take_export.hpp — a take's download as BVH or joint-angle CSV: the take's raw file re-solved
// by `mocapd --replay`'s code (daemon/replay.hpp) with the daemon's config, the calibrations
// the take carries, and optionally another filter (docs/client-protocol.md, "Takes").
//
// The export works in a hidden directory of the take store (<root>/.export-<n>): it copies
// the take's calibration files there (so a re-solve never writes into the take), replays into
// a file there, opens that file, then removes the directory, so the result is an unlinked
// open file that disappears when the download closes it, and nothing is left behind but
// after a crash mid-export (such a directory is removed when the next export starts).
// A requested filter replaces [filter] and every per-segment override, with that filter's
// default parameters.
//
// Threads: any (the web endpoint's export queue); one call at a time per store root is not
// required. Cost: a whole replay, ~90x real time with the default filter; checks `cancel`
// per sample.
#pragma once

#include <atomic>

#include "daemon/config.hpp"
#include "serve/take_export_queue.hpp"
#include "serve/take_store.hpp"

namespace mocap::daemon {

serve::TakeExportResult export_take(const DaemonConfig& config, const serve::TakeStore& store,
                                    const serve::TakeExportRequest& request, const std::atomic<bool>& cancel);

}  // namespace mocap::daemon
