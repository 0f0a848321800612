#include "sim/csv_command.hpp"

#include <fstream>
#include <iostream>

#include "filter_tool/filter_run.hpp"

namespace mocap::sim {

CLI::App* add_csv_command(CLI::App& app, CsvCommandOptions& options) {
    CLI::App* cmd = app.add_subcommand("csv", "Write one sensor's benchmark recording with its reference orientation");
    cmd->add_option("--scenario", options.scenario, "fourati | realistic | magnetic | continuous")
        ->required()
        ->check(CLI::IsMember({"fourati", "realistic", "magnetic", "continuous"}));
    cmd->add_option("--seed", options.seed, "Random seed (same seed, same file)")->capture_default_str();
    cmd->add_option("--frame", options.frame, "Earth frame of the reference columns: enu | ned")
        ->check(CLI::IsMember({"enu", "ned"}))
        ->capture_default_str();
    cmd->add_option("--noise-scale", options.noise_scale, "Multiply every sensor noise sigma (study knob)")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    cmd->add_option("--mag-noise-scale", options.mag_noise_scale, "Multiply the magnetometer noise sigma (study knob)")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    cmd->add_option("--out", options.out_path, "Output CSV file")->required();
    return cmd;
}

tools::Recording to_recording(const Scenario& scenario, bool ned) {
    tools::Recording rec;
    rec.has_reference = true;
    rec.has_movement = true;
    rec.rows.reserve(scenario.rows.size());
    const tools::EarthFrame frame = ned ? tools::EarthFrame::ned : tools::EarthFrame::enu;
    for (const ScenarioRow& row : scenario.rows) {
        tools::RecordingRow r;
        r.sample = row.sample;
        r.q_ref = math::canonical(tools::from_enu(row.q_earth_sensor, frame));
        r.ref_valid = true;
        r.movement = row.moving;
        rec.rows.push_back(r);
    }
    return rec;
}

int run_csv_command(const CsvCommandOptions& options) {
    const auto kind = parse_scenario_kind(options.scenario);
    if (!kind) {
        std::cerr << "mocap-sim csv: unknown scenario '" << options.scenario << "'\n";
        return 2;
    }
    ScenarioOptions scenario_options;
    scenario_options.noise_scale = options.noise_scale;
    scenario_options.mag_noise_scale = options.mag_noise_scale;
    const Scenario scenario = make_scenario(*kind, options.seed, scenario_options);
    std::ofstream out(options.out_path, std::ios::binary | std::ios::trunc);
    if (!out) {
        std::cerr << "mocap-sim csv: cannot open '" << options.out_path << "' for writing\n";
        return 1;
    }
    if (!tools::write_recording_csv(out, to_recording(scenario, options.frame == "ned")) || !out.flush()) {
        std::cerr << "mocap-sim csv: write to '" << options.out_path << "' failed\n";
        return 1;
    }
    return 0;
}

}  // namespace mocap::sim
