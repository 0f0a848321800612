// chain_scenario.hpp — `mocap-sim csv --scenario chain`: a five-segment mechanical arm moved by
// hand, one sensor per segment (docs/simulator.md, "chain").
//
// Geometry: segments seg1..seg5 in series, lengths drawn in [0.2, 0.35] m; each segment frame
// has x along the segment, from its proximal joint to its distal one (the next segment's
// proximal joint). seg1 is the free base, held by the hand at its proximal end. Joints:
//   seg1–seg2  hinge about z (the same axis in both segment frames)
//   seg2–seg3  hinge about z (parallel to the first)
//   seg3–seg4  hinge about y (perpendicular to the other two)
//   seg4–seg5  2-DoF: about seg4's z, then about seg5's y (a universal joint: one axis fixed in
//              each segment, orthogonal)
// Each sensor sits at its segment's middle with a uniformly random mounting rotation, so the
// axes in SENSOR frames (chain.toml) are arbitrary unit vectors.
//
// Motion: still for 3–5 s, then episodes of 6–14 s separated by still pauses of 2–5 s (the
// last lasts at least 2 s). An episode moves a set of joints — each joint alone and the base
// alone once, in a seeded order, then everything at once, then all of them, one of them or a
// random subset — at a speed of its own: every moving degree of freedom glides from its previous posture to a new one
// and swings about it with three sinusoids of 0.06–1.1 Hz, the swing faded in and out with C∞ ramps. The first two
// hinges stay within ±88°, the third within ±55° (it bends the arm up and down), the 2-DoF joint within ±80° and ±61°;
// the hand turns the base up to ±86° in yaw, ±38° in roll, ±20° in pitch and moves it up to ±0.28 m (±0.18 m
// vertically). Everything is analytic in t and C∞, so the linear acceleration is the second derivative of each sensor's
// position (central difference, 0.2 ms, error ~1e-6 m/s²).
//
// Place: the hand holds the base at chain_base_position_m(), over the workbench of the `lab`
// preset (magnetic_env.hpp), the arm pointing east at rest; the sensors move at table height
// and read the field at their own positions.
//
// Deterministic for (options, environment). Thread-safety: pure. Cost: ~1 ms per second of
// recording at 40 Hz in `lab`.
#pragma once

#include <cstdint>

#include "sim/chain_recording.hpp"
#include "sim/magnetic_env.hpp"

namespace mocap::sim {

struct ChainOptions {
    std::uint64_t seed = 1;
    double rate_hz = 40.0;
    double duration_s = 180.0;
    double noise_scale = 1.0;  ///< 0: ideal sensors (no noise, no gyro bias)
};

/// The hand's grip on seg1 at rest, ENU m: 0.35 m above the workbench's top, near its west end.
Vec3 chain_base_position_m();

ChainRecording make_chain_scenario(const ChainOptions& options, const MagneticEnv& env);

}  // namespace mocap::sim
