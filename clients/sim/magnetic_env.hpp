// magnetic_env.hpp — the magnetic field of a room as a function of position, for the
// simulator's sensors (docs/simulator.md, "Magnetic environments").
//
// Model: a uniform earth field plus point dipoles,
//     B(p) = B_earth + Σ μ0/4π · (3 (m·r) r − m |r|²) / |r|⁵,   r = p − source position,
// in µT with m in A·m² and r in m (μ0/4π = 0.1 µT·m/A). A source may be softened by a core
// radius a (|r|² → |r|² + a² in both places): it is then bounded, −m/a³·0.1 µT at its centre,
// like a real object of that size, and exact far away.
// Sources come from two places:
//   floor layers  procedural dipoles tiling the whole plane under the floor (z < 0): one per
//                 square cell, its position in the cell, depth, moment direction and size
//                 drawn from a hash of (seed, layer, cell), so any point of an unbounded room
//                 costs the same and needs no list; a source farther than reach_m
//                 horizontally is faded out smoothly (C²) between reach/2 and reach;
//   dipoles       a finite list (furniture, equipment, a file's own sources).
// Presets (make_magnetic_env_spec): `clean` (earth field only, 50 µT, dip 60°: the simulator's
// field until now), `lab` (reinforced floor, building steel, a steel workbench with a PC, a
// monitor and a vise against the south wall at y = −9 m, two cabinets), `steel-floor` (lab with
// about twice the floor steel, shallower). A TOML file describes the same things (docs/simulator.md has the
// format). The walking area of `mocap-sim stream` (|y| < 8 m) holds only floor sources.
//
// Frames and units: ENU (x east, y north, z up), metres, floor at z = 0, field in µT.
// Deterministic: the same spec gives bit-identical fields on every platform (SimRng's hash).
// Thread-safety: a MagneticEnv is immutable; field_ut may be called from any thread.
// Cost: field_ut of a uniform environment returns the earth field; otherwise ~100–200 dipoles
// per call for the presets (~1–2 µs), no allocation.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "math/quaternion.hpp"

namespace mocap::sim {

using math::Vec3;

/// μ0/4π in µT·m/A: the field of m (A·m²) at r (m) is this · (3(m·r̂)r̂ − m)/|r|³ µT.
inline constexpr double kMu0Over4PiUtMPerA = 0.1;

/// Earth field of the given norm, dip (below the horizon) and declination (magnetic north
/// east of true north), ENU µT.
Vec3 earth_field_enu_ut(double norm_ut, double dip_deg, double declination_deg = 0.0);

/// Field of a dipole of moment m_a_m2 at offset r_m from it (µT), softened by core_radius_m
/// (0: the exact point dipole; r must then be non-zero).
Vec3 dipole_field_ut(const Vec3& m_a_m2, const Vec3& r_m, double core_radius_m = 0.0);

struct MagneticDipole {
    Vec3 position_m = Vec3::Zero();
    Vec3 moment_a_m2 = Vec3::Zero();
    double core_radius_m = 0.0;
};

/// Procedural dipoles under the floor: one per cell_m × cell_m cell, anywhere in the cell,
/// centre depth uniform in [depth_min_m, depth_max_m] below z = 0, moment of uniformly random
/// direction and log-uniform size in [moment_min_a_m2, moment_max_a_m2].
/// The defaults are the `lab` preset's reinforcement layer.
struct FloorLayer {
    double cell_m = 0.3;
    double depth_min_m = 0.08;
    double depth_max_m = 0.15;
    double moment_min_a_m2 = 0.3;
    double moment_max_a_m2 = 1.4;
    double reach_m = 1.5;         ///< horizontal distance beyond which a source is ignored
    double core_radius_m = 0.08;  ///< softening (bounded field even at the floor)
    std::uint64_t seed = 1;
};

struct MagneticEnvSpec {
    std::string name = "clean";
    double earth_norm_ut = 50.0;
    double earth_dip_deg = 60.0;
    double earth_declination_deg = 0.0;
    std::vector<FloorLayer> floor;
    std::vector<MagneticDipole> dipoles;
};

/// Where the `chain` scenario holds its arm: over the workbench of the `lab` and
/// `steel-floor` presets (ENU, m; the table top is at z = 0.75 m).
inline Vec3 workbench_position_m() {
    return {0.0, -9.0, 0.0};
}

/// "clean" | "lab" | "steel-floor" -> the preset with its floor layers seeded from `seed`;
/// nullopt for anything else.
std::optional<MagneticEnvSpec> make_magnetic_env_spec(std::string_view name, std::uint64_t seed);

/// A TOML description (docs/simulator.md); floor layers without a seed get default_seed.
/// nullopt with *error naming the key (and line) on a bad file.
std::optional<MagneticEnvSpec> parse_magnetic_env_toml(std::string_view text, std::string_view source_name,
                                                       std::uint64_t default_seed, std::string* error);

class MagneticEnv {
public:
    explicit MagneticEnv(MagneticEnvSpec spec = {});

    /// A preset name, or else the path of a TOML file. nullopt with *error if neither.
    static std::optional<MagneticEnv> load(const std::string& name_or_path, std::uint64_t seed, std::string* error);

    /// Field at position_m (ENU, m), ENU µT.
    [[nodiscard]] Vec3 field_ut(const Vec3& position_m) const;
    [[nodiscard]] const Vec3& earth_field_ut() const { return earth_ut_; }
    /// No sources: field_ut is the earth field everywhere.
    [[nodiscard]] bool uniform() const { return spec_.floor.empty() && spec_.dipoles.empty(); }
    [[nodiscard]] const MagneticEnvSpec& spec() const { return spec_; }

private:
    MagneticEnvSpec spec_;
    Vec3 earth_ut_;
};

/// Heading of the horizontal field (rad, from north toward east), and the dip (rad, below
/// the horizon), of a field vector in ENU.
double field_heading_rad(const Vec3& b_enu);
double field_dip_rad(const Vec3& b_enu);

}  // namespace mocap::sim
