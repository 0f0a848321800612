#include "sim/field_command.hpp"

#include <cstdio>

#include "sim/magnetic_env.hpp"
#include "sim/magnetic_stats.hpp"

namespace mocap::sim {

CLI::App* add_field_command(CLI::App& app, FieldCommandOptions& o) {
    CLI::App* cmd = app.add_subcommand("field", "Print how a magnetic environment varies over the walking area");
    cmd->add_option("--magnetic-env", o.magnetic_env, "clean | lab | steel-floor | FILE.toml")->capture_default_str();
    cmd->add_option("--seed", o.seed, "Seed of the environment's floor")->capture_default_str();
    cmd->add_option("--points", o.points, "Spots per height")->check(CLI::Range(1, 1000000))->capture_default_str();
    return cmd;
}

int run_field_command(const FieldCommandOptions& o) {
    std::string error;
    const auto env = MagneticEnv::load(o.magnetic_env, o.seed, &error);
    if (!env) {
        std::fprintf(stderr, "mocap-sim field: %s\n", error.c_str());
        return 2;
    }
    const FieldArea area;
    const auto rows = field_stats(*env, kStatHeightsM, o.points, area, o.seed);
    std::printf(
        "%s, seed %llu: %zu spots over x %.0f..%.0f m, y %.0f..%.0f m; heading deviation from the "
        "earth field's, deg\n\n",
        o.magnetic_env.c_str(), static_cast<unsigned long long>(o.seed), rows.empty() ? 0 : rows[0].points,
        area.x_min_m, area.x_max_m, area.y_min_m, area.y_max_m);
    std::printf(
        "| height | z (m) | median | p95 | p99 | max | rms | vs chest p95 | vs chest max | norm p5–p95 (µT) "
        "| dip p5–p95 (deg) |\n");
    std::printf("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n");
    for (std::size_t i = 0; i < rows.size(); ++i) {
        const HeightStats& s = rows[i];
        std::printf("| %s | %.2f | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f–%.1f | %.1f–%.1f |\n",
                    kStatHeightNames[i], s.height_m, s.heading_abs_median_deg, s.heading_abs_p95_deg,
                    s.heading_abs_p99_deg, s.heading_abs_max_deg, s.heading_rms_deg, s.vs_chest_abs_p95_deg,
                    s.vs_chest_abs_max_deg, s.norm_p5_ut, s.norm_p95_ut, s.dip_p5_deg, s.dip_p95_deg);
    }
    return 0;
}

}  // namespace mocap::sim
