// csv_command.hpp — `mocap-sim csv`: writes a benchmark recording with its truth: one sensor's
// CSV (the scenarios of scenario.hpp), or a chain of sensors as CHAIN.toml plus one CSV per
// segment (chain_scenario.hpp, pendulum_scenario.hpp; files in chain_recording.hpp).
//
//   mocap-sim csv --scenario NAME [--seed N] [--frame enu|ned] [--noise-scale X]
//                 [--mag-noise-scale X] --out FILE.csv
//       NAME: any name parse_scenario_kind() accepts (fourati, realistic, magnetic,
//       continuous, ...); rate, duration and field are the scenario's own.
//   mocap-sim csv --scenario chain|pendulum [--seed N] [--frame enu|ned] [--noise-scale X]
//                 [--rate HZ] [--duration S] [--magnetic-env clean|lab|steel-floor|FILE.toml]
//                 --out DIR/NAME.toml
//       defaults: chain 40 Hz, 180 s, lab; pendulum 100 Hz, 210 s, clean. DIR must exist;
//       the CSVs (seg1.csv, ...) and truth.toml are written next to NAME.toml.
//
// Columns t,gx,gy,gz,ax,ay,az,mx,my,mz,qw,qx,qy,qz,movement (recording_csv.hpp); the
// reference is q_earth_sensor in ENU, or in NED with --frame ned (for mocap-filter --frame
// ned, which then reports Euler errors in the paper's frame). The noise scales are study
// knobs (ScenarioOptions); the benchmark uses the defaults (1). For chain and pendulum
// --noise-scale 0 also removes the gyro bias.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

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
    double rate_hz = 0.0;      ///< chain/pendulum: 0 = the scenario's default
    double duration_s = 0.0;   ///< chain/pendulum: 0 = the scenario's default
    std::string magnetic_env;  ///< chain/pendulum: empty = the scenario's default
    std::string out_path;
};

/// Registers the subcommand on app; options are filled when it is parsed.
CLI::App* add_csv_command(CLI::App& app, CsvCommandOptions& options);

/// Runs it: 0 on success, else prints the reason on stderr and returns non-zero.
int run_csv_command(const CsvCommandOptions& options);

/// The scenario as a recording (reference and movement columns), reference in the frame.
tools::Recording to_recording(const Scenario& scenario, bool ned);

/// The names of the single-sensor scenarios parse_scenario_kind() accepts, in enum order.
std::vector<std::string> single_sensor_scenario_names();

}  // namespace mocap::sim
