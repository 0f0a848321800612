#include "sim/csv_command.hpp"

#include <filesystem>
#include <fstream>
#include <iostream>

#include "filter_tool/filter_run.hpp"
#include "sim/chain_scenario.hpp"
#include "sim/pendulum_scenario.hpp"

namespace mocap::sim {
namespace {

bool is_chain_scenario(const std::string& name) {
    return name == "chain" || name == "pendulum";
}

std::string scenario_list() {
    std::string s = "chain | pendulum";
    for (const std::string& n : single_sensor_scenario_names())
        s += " | " + n;
    return s;
}

/// The scenario's rate, duration and field unless the command line sets them.
struct ChainDefaults {
    double rate_hz;
    double duration_s;
    const char* magnetic_env;
};
ChainDefaults chain_defaults(const std::string& scenario) {
    if (scenario == "chain") return {ChainOptions{}.rate_hz, ChainOptions{}.duration_s, "lab"};
    return {PendulumOptions{}.rate_hz, PendulumOptions{}.duration_s, "clean"};
}

int run_chain_command(const CsvCommandOptions& o) {
    const ChainDefaults d = chain_defaults(o.scenario);
    const double rate_hz = o.rate_hz > 0.0 ? o.rate_hz : d.rate_hz;
    const double duration_s = o.duration_s > 0.0 ? o.duration_s : d.duration_s;
    const std::string env_name = !o.magnetic_env.empty() ? o.magnetic_env : d.magnetic_env;
    if (o.mag_noise_scale != 1.0) {
        std::cerr << "mocap-sim csv: --mag-noise-scale applies to the single-sensor scenarios only\n";
        return 2;
    }
    const std::filesystem::path out(o.out_path);
    const std::filesystem::path dir = out.parent_path().empty() ? std::filesystem::path(".") : out.parent_path();
    if (out.filename().empty() || !std::filesystem::is_directory(dir)) {
        std::cerr << "mocap-sim csv: --out must name a TOML file in an existing folder, got '" << o.out_path << "'\n";
        return 1;
    }
    std::string error;
    const auto env = MagneticEnv::load(env_name, o.seed, &error);
    if (!env) {
        std::cerr << "mocap-sim csv: " << error << "\n";
        return 2;
    }
    ChainRecording rec;
    if (o.scenario == "chain") {
        ChainOptions c;
        c.seed = o.seed;
        c.rate_hz = rate_hz;
        c.duration_s = duration_s;
        c.noise_scale = o.noise_scale;
        rec = make_chain_scenario(c, *env);
    } else {
        PendulumOptions p;
        p.seed = o.seed;
        p.rate_hz = rate_hz;
        p.duration_s = duration_s;
        p.noise_scale = o.noise_scale;
        rec = make_pendulum_scenario(p, *env);
    }
    if (!write_chain_files(rec, dir / out.filename(), o.frame == "ned", &error)) {
        std::cerr << "mocap-sim csv: " << error << "\n";
        return 1;
    }
    return 0;
}

}  // namespace

std::vector<std::string> single_sensor_scenario_names() {
    std::vector<std::string> names;
    // ScenarioKind counts up from 0 and scenario_name() answers "unknown" past the last kind.
    for (int i = 0; i < 64; ++i) {
        const std::string name(scenario_name(static_cast<ScenarioKind>(i)));
        if (!parse_scenario_kind(name)) break;
        names.push_back(name);
    }
    return names;
}

CLI::App* add_csv_command(CLI::App& app, CsvCommandOptions& options) {
    CLI::App* cmd = app.add_subcommand("csv", "Write a benchmark recording with its reference orientation");
    cmd->add_option("--scenario", options.scenario, scenario_list())
        ->required()
        ->check(CLI::Validator(
            [](std::string& name) -> std::string {
                if (is_chain_scenario(name) || parse_scenario_kind(name)) return {};
                return "unknown scenario '" + name + "' (" + scenario_list() + ")";
            },
            "SCENARIO"));
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
    cmd->add_option("--rate", options.rate_hz, "chain, pendulum: sample rate, Hz (default 40 chain, 100 pendulum)")
        ->check(CLI::Range(1.0, 2000.0));
    cmd->add_option("--duration", options.duration_s, "chain, pendulum: seconds (default 180 chain, 210 pendulum)")
        ->check(CLI::Range(1.0, 36000.0));
    cmd->add_option("--magnetic-env", options.magnetic_env,
                    "chain, pendulum: clean | lab | steel-floor | FILE.toml (default lab chain, clean pendulum)");
    cmd->add_option("--out", options.out_path, "Output CSV file, or DIR/NAME.toml for chain and pendulum")->required();
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
    if (is_chain_scenario(options.scenario)) return run_chain_command(options);
    const auto kind = parse_scenario_kind(options.scenario);
    if (!kind) {
        std::cerr << "mocap-sim csv: unknown scenario '" << options.scenario << "'\n";
        return 2;
    }
    if (options.rate_hz > 0.0 || options.duration_s > 0.0 || !options.magnetic_env.empty()) {
        std::cerr << "mocap-sim csv: --rate, --duration and --magnetic-env apply to chain and pendulum; '"
                  << options.scenario << "' has its own\n";
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
