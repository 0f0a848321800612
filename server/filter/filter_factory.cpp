#include "filter/filter_factory.hpp"

#include <charconv>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <sstream>
#include <type_traits>
#include <variant>

#include "core/parse_number.hpp"
#include "filter/csmo.hpp"
#include "filter/madgwick.hpp"
#include "filter/mahony.hpp"
#include "filter/mocap_filter.hpp"
#include "filter/particle_filter.hpp"

namespace mocap::filter {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// One key of a Params struct: its name, the member it sets and the values it accepts. A
// number outside [min, max] is refused before the filter's own check (which knows the
// relations between parameters): without an upper bound `beta = 1e308` was accepted and
// made every output NaN. Booleans and the particle filter's seed take any value.
template <class P>
struct Field {
    std::string_view key;
    std::variant<double P::*, bool P::*, int P::*, std::uint64_t P::*> member;
    double min = -kInf;
    double max = kInf;
    bool nan_means_unset = false;  ///< NaN is a value ("not set"), outside the range
};

template <class Number>
bool in_range(Number v, double min, double max, bool nan_ok) {
    if constexpr (std::is_same_v<Number, bool>) {
        return true;
    } else if constexpr (std::is_same_v<Number, double>) {
        return (nan_ok && std::isnan(v)) || (v >= min && v <= max);
    } else {
        return static_cast<double>(v) >= min && static_cast<double>(v) <= max;
    }
}

bool parse_value(std::string_view text, bool& out) {
    for (std::string_view t : {"true", "1", "yes", "on"}) {
        if (text == t) return out = true, true;
    }
    for (std::string_view f : {"false", "0", "no", "off"}) {
        if (text == f) return out = false, true;
    }
    return false;
}

// "nan" is a value, not an error: it is how a parameter says "not set" (dip_deg: use the
// dip measured at start-up), and format_value() writes it so.
bool parse_value(std::string_view text, double& out) {
    if (text == "nan") {
        out = std::numeric_limits<double>::quiet_NaN();
        return true;
    }
    return core::parse_number(text, out);
}

template <class Number>
bool parse_value(std::string_view text, Number& out) {
    return core::parse_number(text, out);
}

std::string format_value(double v) {
    std::ostringstream os;
    os.precision(17);
    os << v;
    return os.str();
}
std::string format_value(bool v) {
    return v ? "true" : "false";
}
template <class Int>
std::string format_value(Int v) {
    return std::to_string(v);
}

std::string cannot_parse_message(std::string_view filter, const std::string& key, const std::string& value) {
    return "parameter \"" + key + "\" of filter \"" + std::string(filter) + "\": cannot parse \"" + value + "\"";
}

std::string out_of_range_message(std::string_view filter, const std::string& key, const std::string& value, double min,
                                 double max) {
    std::string out = "parameter \"";
    out.append(key).append("\" of filter \"").append(filter).append("\": ").append(value);
    out.append(" is outside ").append(format_value(min)).append("..").append(format_value(max));
    return out;
}

// Everything the factory needs to know about one filter type.
template <class P, class F>
struct Entry {
    std::vector<Field<P>> fields;
    std::function<std::string(const P&)> check;  // empty string: valid

    std::unique_ptr<OrientationFilter> make(std::string_view name, const FilterParamList& params,
                                            std::string* error) const {
        P p{};
        // Named references, not a structured binding: clang before 16 cannot capture a
        // binding in the lambda below, and the static analysis parses this file with clang.
        for (const auto& kv : params) {
            const std::string& key = kv.first;
            const std::string& value = kv.second;
            const Field<P>* field = nullptr;
            for (const Field<P>& f : fields) {
                if (f.key == key) field = &f;
            }
            if (field == nullptr) {
                if (error) *error = "filter \"" + std::string(name) + "\" has no parameter \"" + key + "\"";
                return nullptr;
            }
            const bool ok = std::visit([&](auto member) { return parse_value(value, p.*member); }, field->member);
            if (!ok) {
                if (error) *error = cannot_parse_message(name, key, value);
                return nullptr;
            }
            const bool in = std::visit(
                [&](auto member) { return in_range(p.*member, field->min, field->max, field->nan_means_unset); },
                field->member);
            if (!in) {
                if (error) *error = out_of_range_message(name, key, value, field->min, field->max);
                return nullptr;
            }
        }
        if (const std::string msg = check(p); !msg.empty()) {
            if (error) *error = "filter \"" + std::string(name) + "\": " + msg;
            return nullptr;
        }
        return std::make_unique<F>(p);
    }

    std::vector<FilterKey> keys() const {
        const P p{};
        std::vector<FilterKey> out;
        for (const Field<P>& f : fields) {
            out.push_back(
                {f.key, std::visit([&](auto member) { return format_value(p.*member); }, f.member), f.min, f.max});
        }
        return out;
    }
};

const Entry<MocapFilterParams, MocapFilter>& mocap_entry() {
    using P = MocapFilterParams;
    static const Entry<P, MocapFilter> e{{{"tau_acc_s", &P::tau_acc_s, 0.0, 1000.0},
                                          {"tau_mag_s", &P::tau_mag_s, 0.0, 10000.0},
                                          {"rest_bias", &P::rest_bias},
                                          {"motion_bias", &P::motion_bias},
                                          {"bias_sigma_init_deg_s", &P::bias_sigma_init_deg_s, 0.0, 100.0},
                                          {"bias_forgetting_time_s", &P::bias_forgetting_time_s, 0.0, 1e6},
                                          {"bias_clip_deg_s", &P::bias_clip_deg_s, 0.0, 100.0},
                                          {"bias_sigma_motion_deg_s", &P::bias_sigma_motion_deg_s, 0.0, 100.0},
                                          {"bias_vertical_forgetting", &P::bias_vertical_forgetting, 0.0, 1.0},
                                          {"bias_sigma_rest_deg_s", &P::bias_sigma_rest_deg_s, 0.0, 100.0},
                                          {"rest_min_time_s", &P::rest_min_time_s, 0.0, 3600.0},
                                          {"rest_filter_tau_s", &P::rest_filter_tau_s, 0.0, 100.0},
                                          {"rest_th_gyro_deg_s", &P::rest_th_gyro_deg_s, 0.0, 1000.0},
                                          {"rest_th_acc_m_s2", &P::rest_th_acc_m_s2, 0.0, 100.0},
                                          {"gyro_noise_ref_deg_s", &P::gyro_noise_ref_deg_s, 0.0, 100.0},
                                          {"mag_guard", &P::mag_guard},
                                          {"mag_current_tau_s", &P::mag_current_tau_s, 0.0, 100.0},
                                          {"mag_ref_tau_s", &P::mag_ref_tau_s, 0.0, 1e5},
                                          {"mag_norm_th", &P::mag_norm_th, 0.0, 10.0},
                                          {"mag_dip_th_deg", &P::mag_dip_th_deg, 0.0, 180.0},
                                          {"mag_noise_margin", &P::mag_noise_margin, 0.0, 100.0},
                                          {"mag_heading_th_deg", &P::mag_heading_th_deg, 0.0, 180.0},
                                          {"mag_heading_tau_s", &P::mag_heading_tau_s, 0.0, 1000.0},
                                          {"mag_new_time_s", &P::mag_new_time_s, 0.0, 1e5},
                                          {"mag_new_first_time_s", &P::mag_new_first_time_s, 0.0, 1e5},
                                          {"mag_new_min_gyro_deg_s", &P::mag_new_min_gyro_deg_s, 0.0, 2000.0},
                                          {"mag_min_undisturbed_time_s", &P::mag_min_undisturbed_time_s, 0.0, 1e4},
                                          {"mag_max_rejection_time_s", &P::mag_max_rejection_time_s, 0.0, 1e5},
                                          {"mag_rejection_factor", &P::mag_rejection_factor, 1.0, 1000.0},
                                          {"mag_offset_tau_s", &P::mag_offset_tau_s, 0.0, 1e5},
                                          {"mag_offset_ridge", &P::mag_offset_ridge, 0.0, 1.0},
                                          {"mag_offset_min", &P::mag_offset_min, 0.0, 1.0},
                                          {"mag_delay_s", &P::mag_delay_s, -1.0, 0.05},
                                          {"mag_delay_share", &P::mag_delay_share, 0.0, 1.0},
                                          {"max_step_s", &P::max_step_s, 0.0, 3600.0}},
                                         [](const P& p) { return p.check(); }};
    return e;
}

const Entry<MadgwickParams, MadgwickFilter>& madgwick_entry() {
    using P = MadgwickParams;
    static const Entry<P, MadgwickFilter> e{{{"beta", &P::beta, 0.0, 10.0},
                                             {"init_from_first_sample", &P::init_from_first_sample},
                                             {"max_step_s", &P::max_step_s, 0.0, 3600.0}},
                                            [](const P& p) { return p.check(); }};
    return e;
}

const Entry<MahonyParams, MahonyFilter>& mahony_entry() {
    using P = MahonyParams;
    static const Entry<P, MahonyFilter> e{{{"kp", &P::kp, 0.0, 100.0},
                                           {"ki", &P::ki, 0.0, 100.0},
                                           {"bias_clip_rad_s", &P::bias_clip_rad_s, 0.0, 10.0},
                                           {"init_from_first_sample", &P::init_from_first_sample},
                                           {"max_step_s", &P::max_step_s, 0.0, 3600.0}},
                                          [](const P& p) { return p.check(); }};
    return e;
}

const Entry<CsmoParams, Csmo>& csmo_entry() {
    using P = CsmoParams;
    static const Entry<P, Csmo> e{{{"k1", &P::k1, 0.0, 10.0},
                                   {"k2", &P::k2, 0.0, 10.0},
                                   {"k3", &P::k3, 0.0, 10.0},
                                   {"k4", &P::k4, 0.0, 10.0},
                                   {"k5", &P::k5, 0.0, 10.0},
                                   {"k6", &P::k6, 0.0, 10.0},
                                   {"rho", &P::rho, 0.0, 1.0},
                                   {"gain_rate_hz", &P::gain_rate_hz, 0.0, 1e5},
                                   {"q0w", &P::q0w, -1.0, 1.0},
                                   {"q0x", &P::q0x, -1.0, 1.0},
                                   {"q0y", &P::q0y, -1.0, 1.0},
                                   {"q0z", &P::q0z, -1.0, 1.0},
                                   {"init_meas", &P::init_from_measurement},
                                   {"dip_deg", &P::dip_deg, -90.0, 90.0, true},
                                   {"lm_lambda", &P::lm_lambda, 0.0, 1e6},
                                   {"lm_alpha", &P::lm_alpha, 0.0, 10.0},
                                   {"lm_iterations", &P::lm_iterations, 1.0, 100.0},
                                   {"max_step_s", &P::max_step_s, 0.0, 3600.0}},
                                  // CsmoParams has no check of its own: the ranges its code relies on.
                                  [](const P& p) -> std::string {
                                      for (const double k : {p.k1, p.k2, p.k3, p.k4, p.k5, p.k6}) {
                                          if (!(k >= 0.0)) return "gains k1..k6 must be >= 0";
                                      }
                                      if (!(p.rho > 0.0)) return "rho must be > 0";
                                      if (!(p.gain_rate_hz > 0.0)) return "gain_rate_hz must be > 0";
                                      if (!(std::hypot(p.q0w, p.q0x, p.q0y) + std::abs(p.q0z) > 0.0))
                                          return "q0w..q0z must not all be zero";
                                      if (!std::isnan(p.dip_deg) && !(std::abs(p.dip_deg) < 90.0))
                                          return "dip_deg must be NaN or in (-90, 90)";
                                      if (!(p.lm_lambda >= 0.0)) return "lm_lambda must be >= 0";
                                      if (!(p.lm_alpha > 0.0)) return "lm_alpha must be > 0";
                                      if (p.lm_iterations < 1) return "lm_iterations must be >= 1";
                                      if (!(p.max_step_s > 0.0)) return "max_step_s must be > 0";
                                      return {};
                                  }};
    return e;
}

const Entry<ParticleFilterParams, ParticleFilter>& pf_entry() {
    using P = ParticleFilterParams;
    static const Entry<P, ParticleFilter> e{
        {{"particles", &P::particles, 1.0, 65536.0},
         {"seed", &P::seed},
         {"gyro_noise", &P::gyro_noise, 0.0, 10.0},
         {"bias_walk", &P::bias_walk, 0.0, 1.0},
         {"bias_init", &P::bias_init_rad_s, 0.0, 10.0},
         {"meas_tilt", &P::meas_tilt, 0.0, 10.0},
         {"meas_heading", &P::meas_heading, 0.0, 10.0},
         {"resample_frac", &P::resample_frac, 0.0, 1.0},
         {"reg_h", &P::reg_h, 0.0, 1.0},
         {"init_tilt", &P::init_tilt_rad, 0.0, 10.0},
         {"init_heading", &P::init_heading_rad, 0.0, 10.0},
         {"gravity", &P::gravity_m_s2, 1.0, 100.0},
         {"detect", &P::detect},
         {"max_step_s", &P::max_step_s, 0.0, 3600.0}},
        // ParticleFilterParams has no check of its own: the documented ranges (the
        // constructor would silently clamp the particle count).
        [](const P& p) -> std::string {
            if (p.particles < 1 || p.particles > 65536) return "particles must be in 1..65536";
            if (!(p.gyro_noise > 0.0)) return "gyro_noise must be > 0";
            for (const double sigma : {p.bias_walk, p.bias_init_rad_s, p.init_tilt_rad, p.init_heading_rad}) {
                if (!(sigma >= 0.0)) return "noise and init values must be >= 0";
            }
            if (!(p.meas_tilt > 0.0)) return "meas_tilt must be > 0";
            if (!(p.meas_heading > 0.0)) return "meas_heading must be > 0";
            if (!(p.reg_h >= 0.0 && p.reg_h < 1.0)) return "reg_h must be in [0, 1)";
            if (!(p.resample_frac >= 0.0 && p.resample_frac <= 1.0)) return "resample_frac must be in [0, 1]";
            if (!(p.gravity_m_s2 > 0.0)) return "gravity must be > 0";
            if (!(p.max_step_s > 0.0)) return "max_step_s must be > 0";
            return {};
        }};
    return e;
}

// Dispatch on the name; Fn is called with the matching entry.
template <class Fn>
bool with_entry(std::string_view name, Fn&& fn) {
    if (name == "mocap") return fn(mocap_entry()), true;
    if (name == "madgwick") return fn(madgwick_entry()), true;
    if (name == "mahony") return fn(mahony_entry()), true;
    if (name == "csmo") return fn(csmo_entry()), true;
    if (name == "pf") return fn(pf_entry()), true;
    return false;
}

}  // namespace

std::unique_ptr<OrientationFilter> make_filter(std::string_view name, const FilterParamList& params,
                                               std::string* error) {
    std::unique_ptr<OrientationFilter> out;
    const bool known = with_entry(name, [&](const auto& e) { out = e.make(name, params, error); });
    if (!known && error) {
        std::string list;
        for (std::string_view n : filter_names())
            list += (list.empty() ? "" : ", ") + std::string(n);
        *error = "unknown filter \"" + std::string(name) + "\" (known: " + list + ")";
    }
    return out;
}

std::vector<std::string_view> filter_names() {
    return {"mocap", "madgwick", "mahony", "csmo", "pf"};
}

std::vector<FilterKey> filter_keys(std::string_view name) {
    std::vector<FilterKey> out;
    with_entry(name, [&](const auto& e) { out = e.keys(); });
    return out;
}

std::uint32_t filter_cost_weight(std::string_view name) {
    return name == "pf" ? 20 : 1;
}

}  // namespace mocap::filter
