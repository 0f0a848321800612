// pendulum_scenario.hpp — `mocap-sim csv --scenario pendulum`: a two-segment physical pendulum
// swinging from a fixed pivot, one sensor per segment (docs/simulator.md, "pendulum").
//
// Bodies: two uniform bars (pendulum_bodies()); segment frames have x along the bar from its
// proximal joint to its distal end. seg1 hangs from the pivot at pendulum_pivot_m() by an ideal
// hinge whose horizontal axis points in a seeded direction; seg2 hangs from seg1's distal end by
// a joint that is close to a hinge but not one: seg2 = seg1 ⊗ Rx(β(θ)) ⊗ Rz(θ) with
// β(θ) = 7° sin θ, so the instantaneous axis of the relative rotation, (β'(θ) x + Rx(β) z) in
// seg1's frame, wanders around seg1's z as the joint bends (by up to ~10° from its mean).
// chain.toml calls it a hinge with the mean axes (|θ̇|-weighted over the recording), and
// truth.toml gives the largest excursion (axis_wander_deg).
//
// Dynamics: the two generalized coordinates (θ1 at the pivot, θ2 at the lower joint) follow
// the equations of motion of the rigid bars under gravity (Kane's form, M(q) q̈ = Q − bias,
// written out analytically), integrated by RK4 in 8 steps per sample, with light viscous
// damping in both joints (the energy falls by e in ~30 s) and pushes: still hanging for
// 3 s, a push on the upper bar, then every 8–20 s a hand that pumps the upper or the lower
// joint (a torque along its velocity, faded in and out over 2–4 s) toward the energy of a swing
// of the upper bar of 45–85° (30–55° through the lower joint), so the pendulum keeps large
// amplitudes. Each sensor (at its bar's middle, the centre of mass,
// with a uniformly random mounting) reads the accelerations of those equations: centripetal and
// tangential as a real one.
//
// Deterministic for (options, environment). Thread-safety: pure. Cost: ~0.3 s for the default
// 210 s at 100 Hz.
#pragma once

#include <array>
#include <cstdint>

#include "sim/chain_recording.hpp"
#include "sim/magnetic_env.hpp"

namespace mocap::sim {

struct PendulumOptions {
    std::uint64_t seed = 1;
    double rate_hz = 100.0;
    double duration_s = 210.0;
    double noise_scale = 1.0;  ///< 0: ideal sensors (no noise, no gyro bias)
    /// Test hook: released at rest from θ = (70°, −40°) at t = 0, no damping, no pushes, so
    /// the mechanical energy stays what it was.
    bool free_swing = false;
};

/// A uniform bar: length along the segment's x, width along y, thickness along z.
struct PendulumBody {
    double length_m = 0.0;
    double mass_kg = 0.0;
    double width_m = 0.0;
    double thickness_m = 0.0;
};

/// The upper and the lower bar.
std::array<PendulumBody, 2> pendulum_bodies();

/// The pivot, ENU m (the middle of the room, 1.6 m up).
Vec3 pendulum_pivot_m();

ChainRecording make_pendulum_scenario(const PendulumOptions& options, const MagneticEnv& env);

}  // namespace mocap::sim
