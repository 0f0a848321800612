#include "filter_tool/chain_param.hpp"

#include <charconv>
#include <cmath>
#include <string_view>
#include <utility>
#include <vector>

namespace mocap::tools {
namespace {

std::vector<std::pair<std::string_view, double fusion::ChainParams::*>> numeric_keys() {
    using P = fusion::ChainParams;
    return {{"correlation_s", &P::correlation_s},
            {"sigma_axis", &P::sigma_axis},
            {"sigma_rate_rad_s", &P::sigma_rate_rad_s},
            {"sigma_rate_rel", &P::sigma_rate_rel},
            {"min_axis_horizontal", &P::min_axis_horizontal},
            {"min_rate_horizontal_rad_s", &P::min_rate_horizontal_rad_s},
            {"sigma_two_dof_axis", &P::sigma_two_dof_axis},
            {"sigma_two_dof_rate_rad_s", &P::sigma_two_dof_rate_rad_s},
            {"gate_sigma", &P::gate_sigma},
            {"sigma_mag_deg", &P::sigma_mag_deg},
            {"mag_correlation_s", &P::mag_correlation_s},
            {"mag_agree_deg", &P::mag_agree_deg},
            {"field_norm_agree", &P::field_norm_agree},
            {"field_dip_agree_deg", &P::field_dip_agree_deg},
            {"hold_s", &P::hold_s},
            {"search_s", &P::search_s},
            {"search_margin", &P::search_margin},
            {"lost_s", &P::lost_s},
            {"noise_tau_s", &P::noise_tau_s},
            {"min_noise_ratio", &P::min_noise_ratio}};
}

std::vector<std::pair<std::string_view, double fusion::HeadingFilterParams::*>> filter_keys() {
    using H = fusion::HeadingFilterParams;
    return {{"filter.sigma_delta_deg_sqrt_s", &H::sigma_delta_deg_sqrt_s},
            {"filter.sigma_rate_deg_s_sqrt_s", &H::sigma_rate_deg_s_sqrt_s},
            {"filter.rate_sigma_init_deg_s", &H::rate_sigma_init_deg_s},
            {"filter.rate_max_deg_s", &H::rate_max_deg_s},
            {"filter.sigma_max_deg", &H::sigma_max_deg}};
}

}  // namespace

std::string apply_chain_params(const filter::FilterParamList& pairs, fusion::ChainParams& params) {
    for (const auto& [key, text] : pairs) {
        double v = 0.0;
        const auto r = std::from_chars(text.data(), text.data() + text.size(), v);
        if (r.ec != std::errc() || r.ptr != text.data() + text.size() || !std::isfinite(v) || v < 0.0) {
            return std::string("--chain-param ")
                .append(key)
                .append(": '")
                .append(text)
                .append("' is not a non-negative number");
        }
        bool found = false;
        for (const auto& [name, member] : numeric_keys()) {
            if (name == key) {
                params.*member = v;
                found = true;
            }
        }
        for (const auto& [name, member] : filter_keys()) {
            if (name == key) {
                params.filter.*member = v;
                found = true;
            }
        }
        if (!found) return "--chain-param: unknown key '" + key + "'";
    }
    return {};
}

std::string chain_param_keys() {
    std::string out;
    for (const auto& [name, member] : numeric_keys())
        out += (out.empty() ? "" : ", ") + std::string(name);
    for (const auto& [name, member] : filter_keys())
        out += ", " + std::string(name);
    return out;
}

}  // namespace mocap::tools
