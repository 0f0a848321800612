// csv_command.hpp — `mocap-sim csv`: writes one sensor's benchmark recording with its truth.
//
//   mocap-sim csv --scenario fourati|realistic|magnetic|continuous [--seed N] [--frame enu|ned]
//                 [--noise-scale X] [--mag-noise-scale X] --out FILE.csv
//
// Columns t,gx,gy,gz,ax,ay,az,mx,my,mz,qw,qx,qy,qz,movement (recording_csv.hpp); the
// reference is q_earth_sensor in ENU, or in NED with --frame ned (for mocap-filter --frame
// ned, which then reports Euler errors in the paper's frame). The noise scales are study
// knobs (ScenarioOptions); the benchmark uses the defaults (1).
#pragma once

#include <cstdint>
#include <string>

#include <CLI/CLI.hpp>

#include "filter_tool/recording_csv.hpp"
#include "sim/scenario.hpp"

namespace mocap::sim {

struct CsvCommandOptions {
    std::string scenario;
    std::uint64_t seed = 1;
    std::string frame = "enu";
    double noise_scale = 1.0;
    double mag_noise_scale = 1.0;
    std::string out_path;
};

/// Registers the subcommand on app; options are filled when it is parsed.
CLI::App* add_csv_command(CLI::App& app, CsvCommandOptions& options);

/// Runs it: 0 on success, else prints the reason on stderr and returns non-zero.
int run_csv_command(const CsvCommandOptions& options);

/// The scenario as a recording (reference and movement columns), reference in the frame.
tools::Recording to_recording(const Scenario& scenario, bool ned);

}  // namespace mocap::sim
