// magnetic_env.cpp — why: floor sources are drawn from a hash of their cell rather than kept
// in a list, so a subject 2 km away sees the same kind of floor as one at the origin and the
// field is a pure function of position; the fade at reach_m keeps it smooth (a source that
// dropped out abruptly would show up as a step in a moving sensor's magnetometer).
#include "sim/magnetic_env.hpp"

#include <toml++/toml.h>
#include <algorithm>
#include <cmath>
#include <fstream>
#include <numbers>
#include <sstream>

#include "sim/sim_rng.hpp"

namespace mocap::sim {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

/// A uniform [0, 1) number from a hash key and an index (53 bits).
double hashed_uniform(std::uint64_t key, std::uint64_t index) {
    return static_cast<double>(splitmix64(key + index * 0x9E3779B97F4A7C15ull) >> 11) * 0x1.0p-53;
}

std::uint64_t cell_key(std::uint64_t seed, std::size_t layer, std::int64_t ix, std::int64_t iy) {
    std::uint64_t k = splitmix64(seed ^ 0x6D61675F656E76ull);  // "mag_env"
    k = splitmix64(k ^ static_cast<std::uint64_t>(layer));
    k = splitmix64(k ^ static_cast<std::uint64_t>(ix));
    return splitmix64(k ^ static_cast<std::uint64_t>(iy));
}

/// 1 up to half the reach, 0 from the reach on, quintic smootherstep between (C²).
double fade(double rho_m, double reach_m) {
    const double u = std::clamp((rho_m - 0.5 * reach_m) / (0.5 * reach_m), 0.0, 1.0);
    return 1.0 - u * u * u * (u * (6.0 * u - 15.0) + 10.0);
}

Vec3 floor_layer_field_ut(const FloorLayer& layer, std::size_t index, const Vec3& p) {
    Vec3 b = Vec3::Zero();
    const double c = layer.cell_m;
    const auto x0 = static_cast<std::int64_t>(std::floor((p.x() - layer.reach_m) / c));
    const auto x1 = static_cast<std::int64_t>(std::floor((p.x() + layer.reach_m) / c));
    const auto y0 = static_cast<std::int64_t>(std::floor((p.y() - layer.reach_m) / c));
    const auto y1 = static_cast<std::int64_t>(std::floor((p.y() + layer.reach_m) / c));
    const double log_ratio = std::log(layer.moment_max_a_m2 / layer.moment_min_a_m2);
    for (std::int64_t ix = x0; ix <= x1; ++ix) {
        const double cx = static_cast<double>(ix) * c;
        const double dx = std::max({cx - p.x(), p.x() - cx - c, 0.0});
        for (std::int64_t iy = y0; iy <= y1; ++iy) {
            const double cy = static_cast<double>(iy) * c;
            const double dy = std::max({cy - p.y(), p.y() - cy - c, 0.0});
            if (dx * dx + dy * dy >= layer.reach_m * layer.reach_m) continue;  // the whole cell is out of reach
            const std::uint64_t key = cell_key(layer.seed, index, ix, iy);
            const Vec3 source((static_cast<double>(ix) + hashed_uniform(key, 0)) * c,
                              (static_cast<double>(iy) + hashed_uniform(key, 1)) * c,
                              -(layer.depth_min_m + (layer.depth_max_m - layer.depth_min_m) * hashed_uniform(key, 2)));
            const Vec3 r = p - source;
            const double w = fade(std::hypot(r.x(), r.y()), layer.reach_m);
            if (w <= 0.0) continue;
            // Uniform direction on the sphere (Archimedes), log-uniform size.
            const double cz = 2.0 * hashed_uniform(key, 3) - 1.0;
            const double phi = 2.0 * std::numbers::pi * hashed_uniform(key, 4);
            const double s = std::sqrt(std::max(0.0, 1.0 - cz * cz));
            const double size = layer.moment_min_a_m2 * std::exp(log_ratio * hashed_uniform(key, 5));
            b += w * dipole_field_ut(size * Vec3(s * std::cos(phi), s * std::sin(phi), cz), r, layer.core_radius_m);
        }
    }
    return b;
}

// ------------------------------------------------------------------ presets

/// Reinforcement (dense, shallow, weak) and building steel (coarse, deeper, strong). Tuned so
/// that the heading deviation over the walking area falls off with height as docs/simulator.md
/// reports: `lab` p95 ~28° at the ankle, ~6° at the knee, ~2° at the chest.
void add_floor(MagneticEnvSpec& s, std::uint64_t seed, bool steel) {
    FloorLayer rebar;
    rebar.cell_m = 0.3;
    rebar.depth_min_m = steel ? 0.07 : 0.08;
    rebar.depth_max_m = steel ? 0.13 : 0.15;
    rebar.moment_min_a_m2 = steel ? 0.6 : 0.3;
    rebar.moment_max_a_m2 = steel ? 2.4 : 1.4;
    rebar.reach_m = 1.5;
    rebar.core_radius_m = 0.08;
    rebar.seed = seed;
    s.floor.push_back(rebar);
    FloorLayer beams;
    beams.cell_m = 3.0;
    beams.depth_min_m = 0.5;
    beams.depth_max_m = 0.9;
    beams.moment_min_a_m2 = steel ? 70.0 : 40.0;
    beams.moment_max_a_m2 = steel ? 130.0 : 80.0;
    beams.reach_m = 9.0;
    beams.core_radius_m = 0.3;
    beams.seed = seed;
    s.floor.push_back(beams);
}

/// A steel workbench (legs, frame, top) with a PC under it, a monitor and a vise on it, centred on
/// workbench_position_m(), and two steel cabinets further along the same wall. Moments are
/// mostly along the earth field (induced) with some remanence.
void add_furniture(MagneticEnvSpec& s) {
    const Vec3 o = workbench_position_m();
    const Vec3 along_field = earth_field_enu_ut(1.0, 60.0);
    auto add = [&](const Vec3& at, const Vec3& moment, double core) { s.dipoles.push_back({o + at, moment, core}); };
    for (const double x : {-0.7, 0.7}) {
        for (const double y : {-0.35, 0.35})
            add({x, y, 0.37}, 1.2 * Vec3(0.0, 0.0, -1.0) + 0.3 * along_field, 0.08);  // legs
    }
    add({-0.4, -0.1, 0.72}, 2.5 * along_field + Vec3(1.0, 0.3, 0.0), 0.2);  // frame and top
    add({0.4, 0.1, 0.72}, 2.2 * along_field + Vec3(-0.5, 0.8, 0.0), 0.2);
    add({0.0, 0.3, 0.72}, 1.6 * along_field + Vec3(0.6, -0.6, 0.0), 0.2);
    add({0.5, -0.2, 0.25}, Vec3(2.5, -1.5, -3.0), 0.15);                      // PC under the bench
    add({0.2, -0.45, 1.0}, Vec3(-2.0, 1.6, -1.2), 0.2);                       // monitor at the back edge
    add({-0.55, 0.45, 0.8}, 2.2 * along_field + Vec3(1.5, -0.8, 0.0), 0.12);  // a vise on the top
    add({-4.0, -0.5, 0.9}, 8.0 * along_field + Vec3(2.0, 0.0, 0.0), 0.4);     // cabinets
    add({5.0, -0.5, 0.9}, 8.0 * along_field + Vec3(-1.0, 2.0, 0.0), 0.4);
}

// ------------------------------------------------------------------ TOML

struct TomlError {
    std::string message;
};

double number_at(const toml::table& t, std::string_view key, std::string_view where, double fallback, double lo,
                 double hi) {
    const toml::node* n = t.get(key);
    if (n == nullptr) return fallback;
    const std::string at =
        std::string(where) + "." + std::string(key) + " (line " + std::to_string(n->source().begin.line) + ")";
    double v = 0.0;
    if (const auto* i = n->as_integer()) {
        v = static_cast<double>(i->get());
    } else if (const auto* f = n->as_floating_point()) {
        v = f->get();
    } else {
        throw TomlError{at + ": expected a number"};
    }
    if (!std::isfinite(v) || v < lo || v > hi) {
        std::ostringstream s;
        s << at << ": must be between " << lo << " and " << hi;
        throw TomlError{s.str()};
    }
    return v;
}

Vec3 vec3_at(const toml::table& t, std::string_view key, std::string_view where, bool required) {
    const toml::node* n = t.get(key);
    const std::string at = std::string(where) + "." + std::string(key);
    if (n == nullptr) {
        if (required) throw TomlError{at + ": missing"};
        return Vec3::Zero();
    }
    const auto* a = n->as_array();
    const std::string line = " (line " + std::to_string(n->source().begin.line) + ")";
    if (a == nullptr || a->size() != 3) throw TomlError{at + line + ": expected [x, y, z]"};
    Vec3 v;
    for (std::size_t i = 0; i < 3; ++i) {
        const toml::node& e = *a->get(i);
        if (const auto* k = e.as_integer()) {
            v[static_cast<Eigen::Index>(i)] = static_cast<double>(k->get());
        } else if (const auto* f = e.as_floating_point()) {
            v[static_cast<Eigen::Index>(i)] = f->get();
        } else {
            throw TomlError{at + line + ": expected numbers"};
        }
    }
    if (!v.allFinite() || v.norm() > 1e4) throw TomlError{at + line + ": values must be finite and below 1e4"};
    return v;
}

/// [lo, hi] with 0 < lo <= hi <= max (a range key such as depth_m = [0.06, 0.15]).
std::pair<double, double> range_at(const toml::table& t, std::string_view key, std::string_view where,
                                   std::pair<double, double> fallback, double max) {
    const toml::node* n = t.get(key);
    if (n == nullptr) return fallback;
    const auto* a = n->as_array();
    const std::string at =
        std::string(where) + "." + std::string(key) + " (line " + std::to_string(n->source().begin.line) + ")";
    if (a == nullptr || a->size() != 2 || !a->get(0)->is_number() || !a->get(1)->is_number())
        throw TomlError{at + ": expected [min, max]"};
    auto num = [](const toml::node& e) {
        if (const auto* k = e.as_integer()) return static_cast<double>(k->get());
        return e.as_floating_point()->get();
    };
    const double lo = num(*a->get(0)), hi = num(*a->get(1));
    if (!(lo > 0.0) || !(hi >= lo) || !(hi <= max)) {
        std::ostringstream s;
        s << at << ": needs 0 < min <= max <= " << max;
        throw TomlError{s.str()};
    }
    return {lo, hi};
}

void reject_unknown(const toml::table& t, std::string_view where, std::initializer_list<std::string_view> keys) {
    for (const auto& [k, v] : t) {
        if (std::find(keys.begin(), keys.end(), k.str()) == keys.end())
            throw TomlError{std::string(where) + "." + std::string(k.str()) + " (line " +
                            std::to_string(v.source().begin.line) + "): unknown key"};
    }
}

std::vector<const toml::table*> tables_at(const toml::table& root, std::string_view key) {
    std::vector<const toml::table*> out;
    const toml::node* n = root.get(key);
    if (n == nullptr) return out;
    const auto* arr = n->as_array();
    if (arr == nullptr || !arr->is_array_of_tables())
        throw TomlError{std::string(key) + ": expected [[" + std::string(key) + "]] tables"};
    for (const auto& e : *arr)
        out.push_back(e.as_table());
    return out;
}

}  // namespace

Vec3 earth_field_enu_ut(double norm_ut, double dip_deg, double declination_deg) {
    const double dip = dip_deg * kDeg, decl = declination_deg * kDeg;
    const double h = norm_ut * std::cos(dip);
    return {h * std::sin(decl), h * std::cos(decl), -norm_ut * std::sin(dip)};
}

Vec3 dipole_field_ut(const Vec3& m_a_m2, const Vec3& r_m, double core_radius_m) {
    const double r2 = r_m.squaredNorm() + core_radius_m * core_radius_m;
    const double inv_r = 1.0 / std::sqrt(r2);
    const double inv_r5 = inv_r * inv_r * inv_r * inv_r * inv_r;
    return kMu0Over4PiUtMPerA * inv_r5 * (3.0 * m_a_m2.dot(r_m) * r_m - r2 * m_a_m2);
}

std::optional<MagneticEnvSpec> make_magnetic_env_spec(std::string_view name, std::uint64_t seed) {
    MagneticEnvSpec s;
    s.name = std::string(name);
    if (name == "clean") return s;
    if (name == "lab") {
        add_floor(s, seed, false);
        add_furniture(s);
        return s;
    }
    if (name == "steel-floor") {
        add_floor(s, seed, true);
        add_furniture(s);
        return s;
    }
    return std::nullopt;
}

std::optional<MagneticEnvSpec> parse_magnetic_env_toml(std::string_view text, std::string_view source_name,
                                                       std::uint64_t default_seed, std::string* error) {
    MagneticEnvSpec s;
    s.name = std::string(source_name);
    try {
        const toml::table root = toml::parse(text, source_name);
        reject_unknown(root, "(top)", {"earth", "floor", "dipole"});
        if (const toml::node* e = root.get("earth")) {
            const auto* t = e->as_table();
            if (t == nullptr) throw TomlError{"earth: expected a table [earth]"};
            reject_unknown(*t, "earth", {"norm_ut", "dip_deg", "declination_deg"});
            s.earth_norm_ut = number_at(*t, "norm_ut", "earth", s.earth_norm_ut, 1.0, 1000.0);
            s.earth_dip_deg = number_at(*t, "dip_deg", "earth", s.earth_dip_deg, -90.0, 90.0);
            s.earth_declination_deg = number_at(*t, "declination_deg", "earth", 0.0, -180.0, 180.0);
        }
        for (const toml::table* t : tables_at(root, "floor")) {
            const std::string where = "floor[" + std::to_string(s.floor.size()) + "]";
            reject_unknown(*t, where, {"cell_m", "depth_m", "moment_a_m2", "reach_m", "core_radius_m", "seed"});
            FloorLayer f;
            f.cell_m = number_at(*t, "cell_m", where, f.cell_m, 0.1, 20.0);
            std::tie(f.depth_min_m, f.depth_max_m) =
                range_at(*t, "depth_m", where, {f.depth_min_m, f.depth_max_m}, 10.0);
            std::tie(f.moment_min_a_m2, f.moment_max_a_m2) =
                range_at(*t, "moment_a_m2", where, {f.moment_min_a_m2, f.moment_max_a_m2}, 1e4);
            f.reach_m = number_at(*t, "reach_m", where, f.reach_m, f.cell_m, 50.0);
            f.core_radius_m = number_at(*t, "core_radius_m", where, f.core_radius_m, 0.0, 5.0);
            f.seed = static_cast<std::uint64_t>(
                number_at(*t, "seed", where, static_cast<double>(default_seed), 0.0, 9007199254740992.0));
            s.floor.push_back(f);
        }
        for (const toml::table* t : tables_at(root, "dipole")) {
            const std::string where = "dipole[" + std::to_string(s.dipoles.size()) + "]";
            reject_unknown(*t, where, {"position_m", "moment_a_m2", "core_radius_m"});
            MagneticDipole d;
            d.position_m = vec3_at(*t, "position_m", where, true);
            d.moment_a_m2 = vec3_at(*t, "moment_a_m2", where, true);
            d.core_radius_m = number_at(*t, "core_radius_m", where, 0.0, 0.0, 5.0);
            s.dipoles.push_back(d);
        }
    } catch (const toml::parse_error& e) {
        std::ostringstream m;
        m << source_name << ": " << e.description() << " (line " << e.source().begin.line << ")";
        *error = m.str();
        return std::nullopt;
    } catch (const TomlError& e) {
        *error = std::string(source_name) + ": " + e.message;
        return std::nullopt;
    }
    return s;
}

MagneticEnv::MagneticEnv(MagneticEnvSpec spec)
    : spec_(std::move(spec)),
      earth_ut_(earth_field_enu_ut(spec_.earth_norm_ut, spec_.earth_dip_deg, spec_.earth_declination_deg)) {}

std::optional<MagneticEnv> MagneticEnv::load(const std::string& name_or_path, std::uint64_t seed, std::string* error) {
    if (auto preset = make_magnetic_env_spec(name_or_path, seed)) return MagneticEnv(std::move(*preset));
    std::ifstream in(name_or_path, std::ios::binary);
    if (!in) {
        *error = "magnetic environment '" + name_or_path + "' is neither clean, lab, steel-floor nor a readable file";
        return std::nullopt;
    }
    std::ostringstream text;
    text << in.rdbuf();
    auto spec = parse_magnetic_env_toml(text.str(), name_or_path, seed, error);
    if (!spec) return std::nullopt;
    return MagneticEnv(std::move(*spec));
}

Vec3 MagneticEnv::field_ut(const Vec3& position_m) const {
    Vec3 b = earth_ut_;
    for (std::size_t i = 0; i < spec_.floor.size(); ++i)
        b += floor_layer_field_ut(spec_.floor[i], i, position_m);
    for (const MagneticDipole& d : spec_.dipoles)
        b += dipole_field_ut(d.moment_a_m2, position_m - d.position_m, d.core_radius_m);
    return b;
}

double field_heading_rad(const Vec3& b_enu) {
    return std::atan2(b_enu.x(), b_enu.y());
}

double field_dip_rad(const Vec3& b_enu) {
    return std::atan2(-b_enu.z(), std::hypot(b_enu.x(), b_enu.y()));
}

}  // namespace mocap::sim
