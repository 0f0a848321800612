#include "sim/magnetic_stats.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "sim/sim_rng.hpp"

namespace mocap::sim {
namespace {

constexpr double kRadToDeg = 180.0 / std::numbers::pi;
constexpr double kChestM = 1.30;

double percentile(std::vector<double> v, double p) {
    if (v.empty()) return 0.0;
    const auto k = static_cast<std::size_t>(std::lround(p * static_cast<double>(v.size() - 1)));
    std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
    return v[k];
}

double wrap_deg(double a) {
    a = std::fmod(a + 180.0, 360.0);
    if (a <= 0.0) a += 360.0;
    return a - 180.0;
}

}  // namespace

std::vector<HeightStats> field_stats(const MagneticEnv& env, std::span<const double> heights_m, std::size_t points,
                                     const FieldArea& area, std::uint64_t seed) {
    const double w = area.x_max_m - area.x_min_m, h = area.y_max_m - area.y_min_m;
    const auto nx =
        std::max<std::size_t>(1, static_cast<std::size_t>(std::lround(std::sqrt(static_cast<double>(points) * w / h))));
    const std::size_t ny = std::max<std::size_t>(1, (points + nx - 1) / nx);
    SimRng rng(seed, 77);
    std::vector<std::pair<double, double>> spots;
    for (std::size_t i = 0; i < nx; ++i) {
        for (std::size_t j = 0; j < ny; ++j)
            spots.emplace_back(area.x_min_m + w * (static_cast<double>(i) + rng.uniform()) / static_cast<double>(nx),
                               area.y_min_m + h * (static_cast<double>(j) + rng.uniform()) / static_cast<double>(ny));
    }
    const double earth_heading = field_heading_rad(env.earth_field_ut());
    auto deviation_deg = [&](const Vec3& b) { return wrap_deg((field_heading_rad(b) - earth_heading) * kRadToDeg); };
    std::vector<double> chest;
    chest.reserve(spots.size());
    for (const auto& [x, y] : spots)
        chest.push_back(deviation_deg(env.field_ut(Vec3(x, y, kChestM))));

    std::vector<HeightStats> out;
    for (const double z : heights_m) {
        std::vector<double> abs_dev, vs_chest, norm, dip;
        double sum2 = 0.0;
        for (std::size_t k = 0; k < spots.size(); ++k) {
            const Vec3 b = env.field_ut(Vec3(spots[k].first, spots[k].second, z));
            const double d = deviation_deg(b);
            abs_dev.push_back(std::abs(d));
            vs_chest.push_back(std::abs(wrap_deg(d - chest[k])));
            norm.push_back(b.norm());
            dip.push_back(field_dip_rad(b) * kRadToDeg);
            sum2 += d * d;
        }
        HeightStats s;
        s.height_m = z;
        s.points = spots.size();
        s.heading_abs_median_deg = percentile(abs_dev, 0.5);
        s.heading_abs_p95_deg = percentile(abs_dev, 0.95);
        s.heading_abs_p99_deg = percentile(abs_dev, 0.99);
        s.heading_abs_max_deg = *std::max_element(abs_dev.begin(), abs_dev.end());
        s.heading_rms_deg = std::sqrt(sum2 / static_cast<double>(spots.size()));
        s.vs_chest_abs_p95_deg = percentile(vs_chest, 0.95);
        s.vs_chest_abs_max_deg = *std::max_element(vs_chest.begin(), vs_chest.end());
        s.norm_p5_ut = percentile(norm, 0.05);
        s.norm_p95_ut = percentile(norm, 0.95);
        s.dip_p5_deg = percentile(dip, 0.05);
        s.dip_p95_deg = percentile(dip, 0.95);
        out.push_back(s);
    }
    return out;
}

}  // namespace mocap::sim
