// field_command.hpp — `mocap-sim field`: prints how a magnetic environment's field varies with
// position at the heights of a standing subject's sensors (magnetic_stats.hpp), as the
// Markdown table docs/simulator.md quotes.
//
//   mocap-sim field [--magnetic-env clean|lab|steel-floor|FILE] [--seed N] [--points N]
//
// Exit code: 0, or 2 for an environment that cannot be loaded.
#pragma once

#include <cstdint>
#include <string>

#include <CLI/CLI.hpp>

namespace mocap::sim {

struct FieldCommandOptions {
    std::string magnetic_env = "lab";
    std::uint64_t seed = 1;
    std::size_t points = 20000;
};

CLI::App* add_field_command(CLI::App& app, FieldCommandOptions& options);
int run_field_command(const FieldCommandOptions& options);

}  // namespace mocap::sim
