// take_args.hpp — what `mocapd --replay` and `mocapd --play` accept: raw recording files
// (serve/raw_recorder.hpp) and takes (serve/take_store.hpp), by name in the takes of
// [outputs].record_dir or by the take's directory. A take stands for its raw files in
// recording order. A file path wins over a take of the same name.
#pragma once

#include <optional>
#include <string>
#include <vector>

namespace mocap::daemon {

/// The raw files `args` name, in order; nullopt + *error naming the argument that is neither
/// a file nor a take, or a take without a raw file.
std::optional<std::vector<std::string>> expand_take_args(const std::vector<std::string>& args,
                                                         const std::string& record_dir, std::string* error);

}  // namespace mocap::daemon
