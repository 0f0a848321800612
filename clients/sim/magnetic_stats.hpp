// magnetic_stats.hpp — how a magnetic environment (magnetic_env.hpp) varies over a floor
// area at the heights of a standing subject's sensors: the numbers docs/simulator.md quotes
// (`mocap-sim field` prints them; tests/clients/magnetic_env_test.cpp bounds them).
//
// Points are spread over the area with a seeded jitter on a regular grid, the same points at
// every height, so a column is the field a vertical line of sensors (a standing subject)
// would see. The heading deviation is field_heading(B) − field_heading(B_earth), wrapped to
// (−180°, 180°]: what a magnetometer-based heading would be off by at that spot.
//
// Thread-safety: pure functions. Cost: points × heights field evaluations (~1 µs each).
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "sim/magnetic_env.hpp"

namespace mocap::sim {

/// The heights docs/simulator.md reports (m): ankle, knee, hip, chest, head of a 1.75 m
/// subject (the foot sensor sits lower, ~0.03 m).
inline constexpr double kStatHeightsM[] = {0.08, 0.50, 0.95, 1.30, 1.70};
inline constexpr const char* kStatHeightNames[] = {"ankle", "knee", "hip", "chest", "head"};

struct FieldArea {
    double x_min_m = -10.0, x_max_m = 30.0;  ///< three subjects 10 m apart, 4 m circles
    double y_min_m = -8.0, y_max_m = 8.0;    ///< the walking strip (furniture stays outside)
};

struct HeightStats {
    double height_m = 0.0;
    std::size_t points = 0;
    double heading_abs_median_deg = 0.0;  ///< |heading deviation|
    double heading_abs_p95_deg = 0.0;
    double heading_abs_p99_deg = 0.0;
    double heading_abs_max_deg = 0.0;
    double heading_rms_deg = 0.0;
    double vs_chest_abs_p95_deg = 0.0;  ///< |deviation here − deviation at 1.30 m|, same spot
    double vs_chest_abs_max_deg = 0.0;
    double norm_p5_ut = 0.0, norm_p95_ut = 0.0;
    double dip_p5_deg = 0.0, dip_p95_deg = 0.0;
};

/// One row per height; `points` spots (rounded to a grid) over the area.
std::vector<HeightStats> field_stats(const MagneticEnv& env, std::span<const double> heights_m, std::size_t points,
                                     const FieldArea& area = {}, std::uint64_t seed = 1);

}  // namespace mocap::sim
