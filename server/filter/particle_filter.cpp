#include "filter/particle_filter.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <numbers>

#include "math/markley_average.hpp"

namespace mocap::filter {

namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;
constexpr int kTableBits = 12;
constexpr int kTableSize = 1 << kTableBits;
constexpr std::uint64_t kTableMask = kTableSize - 1;

// Standard-normal quantiles at (k + 0.5) / 4096, rescaled to unit variance. A lookup costs
// ~1 ns against ~20 ns for Box–Muller, and is the same on every standard library. The
// tails stop at ±3.7σ, which is harmless for process noise and jitter.
const std::array<double, kTableSize>& normal_table() {
    static const std::array<double, kTableSize> table = [] {
        std::array<double, kTableSize> t{};
        for (int k = 0; k < kTableSize; ++k) {
            const double p = (k + 0.5) / kTableSize;
            double lo = -10.0, hi = 10.0;  // bisection on Φ(z) = erfc(−z/√2)/2: exact, once
            for (int it = 0; it < 60; ++it) {
                const double mid = 0.5 * (lo + hi);
                (0.5 * std::erfc(-mid / std::numbers::sqrt2) < p ? lo : hi) = mid;
            }
            t[k] = 0.5 * (lo + hi);
        }
        double var = 0.0;
        for (double z : t)
            var += z * z;
        const double s = 1.0 / std::sqrt(var / kTableSize);
        for (double& z : t)
            z *= s;
        return t;
    }();
    return table;
}

std::uint64_t splitmix64(std::uint64_t& x) {
    std::uint64_t z = (x += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

inline std::uint64_t rotl(std::uint64_t x, int k) {
    return (x << k) | (x >> (64 - k));
}

// exp([0, δ]) for a half-angle vector δ: a Taylor form below 0.1 rad (error < 2e-9, and
// the caller normalises), sin/cos above.
inline void small_exp(double dx, double dy, double dz, double& w, double& s) {
    const double t2 = dx * dx + dy * dy + dz * dz;
    if (t2 < 1e-2) {
        w = 1.0 - t2 * (0.5 - t2 / 24.0);
        s = 1.0 - t2 * (1.0 / 6.0 - t2 / 120.0);
    } else {
        const double t = std::sqrt(t2);
        w = std::cos(t);
        s = std::sin(t) / t;
    }
}

// exp(x) for x <= 0 to ~1e-7 relative (0 below −700): 2^(x·log2 e) split into an
// exponent and a degree-7 polynomial of the fraction. Branch-free, so the weight loop
// vectorises; the weights are normalised right after, so 1e-7 is far below what matters.
inline double exp_nonpositive(double x) {
    x = x < -700.0 ? -700.0 : x;
    const double t = x * 1.4426950408889634;
    const auto ti = static_cast<std::int64_t>(t);  // truncates toward zero (t <= 0)
    const std::int64_t k = ti - (t < static_cast<double>(ti) ? 1 : 0);
    const double f = (t - static_cast<double>(k)) * 0.6931471805599453;  // in [0, ln 2)
    const double p =
        1.0 +
        f * (1.0 + f * (0.5 + f * (1.0 / 6 + f * (1.0 / 24 + f * (1.0 / 120 + f * (1.0 / 720 + f * (1.0 / 5040)))))));
    return p * std::bit_cast<double>(static_cast<std::uint64_t>(k + 1023) << 52);
}

// out = normalise(a ⊗ b), Hamilton product written out for the particle loops.
struct Q4 {
    double w, x, y, z;
};
inline Q4 mul_unit(const Q4& a, const Q4& b) {
    const double nw = a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z;
    const double nx = a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y;
    const double ny = a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x;
    const double nz = a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w;
    const double inv = 1.0 / std::sqrt(nw * nw + nx * nx + ny * ny + nz * nz);
    return {nw * inv, nx * inv, ny * inv, nz * inv};
}

}  // namespace

void ParticleFilter::Rng::seed(std::uint64_t x) {
    for (std::uint64_t& v : s)
        v = splitmix64(x);
}

std::uint64_t ParticleFilter::Rng::next() {
    const std::uint64_t result = s[0] + s[3];
    const std::uint64_t t = s[1] << 17;
    s[2] ^= s[0];
    s[3] ^= s[1];
    s[1] ^= s[2];
    s[0] ^= s[3];
    s[2] ^= t;
    s[3] = rotl(s[3], 45);
    return result;
}

void ParticleFilter::fill_noise() {
    const auto& t = normal_table();
    double* z = noise_.data();
    const std::size_t n = static_cast<std::size_t>(n_);
    // xoshiro256+'s low bits are its weakest: take three 12-bit indices from the top 36.
    for (std::size_t i = 0; i < n; ++i) {
        const std::uint64_t a = rng_.next(), b = rng_.next();
        z[i] = t[(a >> 52) & kTableMask];
        z[n + i] = t[(a >> 40) & kTableMask];
        z[2 * n + i] = t[(a >> 28) & kTableMask];
        z[3 * n + i] = t[(b >> 52) & kTableMask];
        z[4 * n + i] = t[(b >> 40) & kTableMask];
        z[5 * n + i] = t[(b >> 28) & kTableMask];
    }
}

ParticleFilter::ParticleFilter(const ParticleFilterParams& params)
    : params_(params), n_(std::clamp(params.particles, 1, 65536)), clock_(params.max_step_s) {
    lma_.max_iterations = std::max(1, params.lm_iterations);
    lma_.tolerance_rad = 1e-6;
    for (auto* v : {&qw_, &qx_, &qy_, &qz_, &bx_, &by_, &bz_, &w_, &cost_, &qw_tmp_, &qx_tmp_, &qy_tmp_, &qz_tmp_,
                    &bx_tmp_, &by_tmp_, &bz_tmp_})
        v->assign(static_cast<std::size_t>(n_), 0.0);
    noise_.assign(6 * static_cast<std::size_t>(n_), 0.0);
    reset();
}

void ParticleFilter::reset() {
    state_ = ParticleFilterState{};
    clock_.reset();
    rng_.seed(params_.seed);
    std::fill(qw_.begin(), qw_.end(), 1.0);
    std::fill(qx_.begin(), qx_.end(), 0.0);
    std::fill(qy_.begin(), qy_.end(), 0.0);
    std::fill(qz_.begin(), qz_.end(), 0.0);
    std::fill(bx_.begin(), bx_.end(), 0.0);
    std::fill(by_.begin(), by_.end(), 0.0);
    std::fill(bz_.begin(), bz_.end(), 0.0);
    std::fill(w_.begin(), w_.end(), 1.0 / n_);
}

math::Quat ParticleFilter::particle(int i) const {
    return math::Quat(qw_[i], qx_[i], qy_[i], qz_[i]);
}
math::Vec3 ParticleFilter::particle_bias(int i) const {
    return {bx_[i], by_[i], bz_[i]};
}
double ParticleFilter::weight(int i) const {
    return w_[i];
}

bool ParticleFilter::measure(const ImuSample& sample, math::Quat& q_m) const {
    if (!sample.has_mag()) return false;
    const math::Vec3 a = math::to_vec3(sample.accel_m_s2), m = math::to_vec3(sample.mag_ut);
    if (!(std::abs(a.norm() / params_.gravity_m_s2 - 1.0) <= params_.accel_gate)) return false;
    AttitudeSolution s;
    if (std::isfinite(params_.dip_deg)) {
        s = solve_lma(a, m, field_direction_enu(params_.dip_deg * kDegToRad),
                      state_.initialised ? state_.q_earth_sensor : math::Quat::Identity(), lma_);
    } else {
        // Only the horizontal direction of the reference matters to TRIAD.
        s = solve_triad(a, m, field_direction_enu(0.0), lma_);
    }
    if (!s.ok()) return false;
    q_m = s.q_earth_sensor;
    return true;
}

void ParticleFilter::initialise(const math::Quat& q_m) {
    const double st = 0.5 * params_.init_tilt_rad, sh = 0.5 * params_.init_heading_rad;
    fill_noise();
    const double* z = noise_.data();
    for (int i = 0; i < n_; ++i) {
        double dw, s;
        const double dx = st * z[i], dy = st * z[n_ + i], dz = sh * z[2 * n_ + i];
        small_exp(dx, dy, dz, dw, s);
        const math::Quat q = (math::Quat(dw, s * dx, s * dy, s * dz) * q_m).normalized();
        qw_[i] = q.w();
        qx_[i] = q.x();
        qy_[i] = q.y();
        qz_[i] = q.z();
        bx_[i] = params_.bias_init_rad_s * z[3 * n_ + i];
        by_[i] = params_.bias_init_rad_s * z[4 * n_ + i];
        bz_[i] = params_.bias_init_rad_s * z[5 * n_ + i];
        w_[i] = 1.0 / n_;
    }
    state_.initialised = true;
    state_.q_measured = q_m;
    state_.q_earth_sensor = math::canonical(q_m);
    estimate();
    state_.n_eff = n_;
}

void ParticleFilter::predict(const math::Vec3& gyro, double dt) {
    const double h = 0.5 * dt;
    const double gs = params_.gyro_noise_rad_s * h;
    const double bs = params_.bias_walk_rad_s2 * std::sqrt(dt);
    fill_noise();
    const double* z = noise_.data();
    const int n = n_;
    double* __restrict qw = qw_.data();
    double* __restrict qx = qx_.data();
    double* __restrict qy = qy_.data();
    double* __restrict qz = qz_.data();
    double* __restrict bx = bx_.data();
    double* __restrict by = by_.data();
    double* __restrict bz = bz_.data();
    // Half-angle bound: rate + 1 rad/s of bias + 4σ of noise. Below 0.1 rad every particle
    // takes the branch-free Taylor path (the loop vectorises); above, sin/cos per particle.
    const double bound = (gyro.norm() + 1.0) * h + 4.0 * std::sqrt(3.0) * gs;
    if (bound >= 0.1) {
        for (int i = 0; i < n; ++i) {
            const double dx = (gyro.x() - bx[i]) * h + gs * z[i];
            const double dy = (gyro.y() - by[i]) * h + gs * z[n + i];
            const double dz = (gyro.z() - bz[i]) * h + gs * z[2 * n + i];
            double pw, s;
            small_exp(dx, dy, dz, pw, s);
            const Q4 q = mul_unit({qw[i], qx[i], qy[i], qz[i]}, {pw, s * dx, s * dy, s * dz});
            qw[i] = q.w;
            qx[i] = q.x;
            qy[i] = q.y;
            qz[i] = q.z;
        }
    } else {
        for (int i = 0; i < n; ++i) {
            const double dx = (gyro.x() - bx[i]) * h + gs * z[i];
            const double dy = (gyro.y() - by[i]) * h + gs * z[n + i];
            const double dz = (gyro.z() - bz[i]) * h + gs * z[2 * n + i];
            const double t2 = dx * dx + dy * dy + dz * dz;
            const double pw = 1.0 - t2 * (0.5 - t2 / 24.0);
            const double s = 1.0 - t2 * (1.0 / 6.0 - t2 / 120.0);
            const double px = s * dx, py = s * dy, pz = s * dz;
            const double aw = qw[i], ax = qx[i], ay = qy[i], az = qz[i];
            const double nw = aw * pw - ax * px - ay * py - az * pz;
            const double nx = aw * px + ax * pw + ay * pz - az * py;
            const double ny = aw * py - ax * pz + ay * pw + az * px;
            const double nz = aw * pz + ax * py - ay * px + az * pw;
            // |q| = 1 ± 1e-8 here: one Newton step of 1/√x around 1 renormalises to rounding.
            const double inv = 1.5 - 0.5 * (nw * nw + nx * nx + ny * ny + nz * nz);
            qw[i] = nw * inv;
            qx[i] = nx * inv;
            qy[i] = ny * inv;
            qz[i] = nz * inv;
        }
    }
    for (int i = 0; i < n; ++i) {
        bx[i] += bs * z[3 * n + i];
        by[i] += bs * z[4 * n + i];
        bz[i] += bs * z[5 * n + i];
    }
}

bool ParticleFilter::weigh(const math::Quat& q_m) {
    // e = q_i ⊗ q_m*: its vector part is sin(θ/2)·axis in the earth frame; z is heading.
    const double pw = q_m.w(), px = -q_m.x(), py = -q_m.y(), pz = -q_m.z();
    // ½ (2v)² / σ² = 2 v² / σ²
    const double kt = 2.0 / (params_.meas_tilt_rad * params_.meas_tilt_rad);
    const double kh = 2.0 / (params_.meas_heading_rad * params_.meas_heading_rad);
    double cmin = std::numeric_limits<double>::infinity();
    for (int i = 0; i < n_; ++i) {
        const double qw = qw_[i], qx = qx_[i], qy = qy_[i], qz = qz_[i];
        const double ex = qw * px + qx * pw + qy * pz - qz * py;
        const double ey = qw * py - qx * pz + qy * pw + qz * px;
        const double ez = qw * pz + qx * py - qy * px + qz * pw;
        const double c = kt * (ex * ex + ey * ey) + kh * ez * ez;
        cost_[i] = c;
        cmin = std::min(cmin, c);
    }
    // Subtracting the best cost keeps the largest likelihood at 1: no underflow of them all.
    double sum = 0.0;
    for (int i = 0; i < n_; ++i) {
        w_[i] *= exp_nonpositive(cmin - cost_[i]);
        sum += w_[i];
    }
    if (!(sum > 1e-300) || !std::isfinite(sum)) return false;
    const double inv = 1.0 / sum;
    double s2 = 0.0;
    for (int i = 0; i < n_; ++i) {
        w_[i] *= inv;
        s2 += w_[i] * w_[i];
    }
    state_.n_eff = 1.0 / s2;
    return true;
}

void ParticleFilter::estimate() {
    math::QuatAccumulator acc;
    acc.add(qw_.data(), qx_.data(), qy_.data(), qz_.data(), w_.data(), n_);
    double bx = 0.0, by = 0.0, bz = 0.0;
    for (int i = 0; i < n_; ++i) {
        bx += w_[i] * bx_[i];
        by += w_[i] * by_[i];
        bz += w_[i] * bz_[i];
    }
    state_.q_earth_sensor = acc.mean(state_.q_earth_sensor);
    state_.gyro_bias_rad_s = math::Vec3(bx, by, bz);
}

void ParticleFilter::resample() {
    // Systematic: one uniform offset, N evenly spaced pointers into the weight CDF.
    const double step = 1.0 / n_;
    double u = step * (static_cast<double>(rng_.next() >> 11) * 0x1.0p-53);
    double c = w_[0];
    int j = 0;
    for (int i = 0; i < n_; ++i) {
        while (u > c && j < n_ - 1)
            c += w_[++j];
        qw_tmp_[i] = qw_[j];
        qx_tmp_[i] = qx_[j];
        qy_tmp_[i] = qy_[j];
        qz_tmp_[i] = qz_[j];
        bx_tmp_[i] = bx_[j];
        by_tmp_[i] = by_[j];
        bz_tmp_[i] = bz_[j];
        u += step;
    }
    qw_.swap(qw_tmp_);
    qx_.swap(qx_tmp_);
    qy_.swap(qy_tmp_);
    qz_.swap(qz_tmp_);
    bx_.swap(bx_tmp_);
    by_.swap(by_tmp_);
    bz_.swap(bz_tmp_);
    std::fill(w_.begin(), w_.end(), step);
    ++state_.resamples;
}

void ParticleFilter::regularise() {
    // Spread of the resampled cloud around the estimate (sensor-frame small angles), and
    // of the bias particles around their mean.
    const math::Quat& m = state_.q_earth_sensor;
    const double mw = m.w(), mx = -m.x(), my = -m.y(), mz = -m.z();  // m*
    double e2 = 0.0;
    math::Vec3 bsum = math::Vec3::Zero(), b2 = math::Vec3::Zero();
    for (int i = 0; i < n_; ++i) {
        const double qw = qw_[i], qx = qx_[i], qy = qy_[i], qz = qz_[i];
        // vec(m* ⊗ q_i)
        const double ex = mw * qx + mx * qw + my * qz - mz * qy;
        const double ey = mw * qy - mx * qz + my * qw + mz * qx;
        const double ez = mw * qz + mx * qy - my * qx + mz * qw;
        e2 += ex * ex + ey * ey + ez * ez;
        const math::Vec3 b(bx_[i], by_[i], bz_[i]);
        bsum += b;
        b2 += b.cwiseAbs2();
    }
    const double inv_n = 1.0 / n_;
    // Per-axis σ of the angle: (2 sin(θ/2))² ≈ θ², averaged over 3 axes.
    const double spread = std::sqrt(4.0 * e2 * inv_n / 3.0);
    const double sq = 0.5 * std::max(params_.min_jitter_rad, params_.reg_h * spread);
    const math::Vec3 bmean = bsum * inv_n;
    const math::Vec3 bstd = (b2 * inv_n - bmean.cwiseAbs2()).cwiseMax(0.0).cwiseSqrt();
    const double a = std::clamp(params_.bias_shrink, 0.0, 1.0);
    const double kj = std::sqrt(std::max(0.0, 1.0 - a * a));
    const math::Vec3 sb = (kj * bstd).cwiseMax(params_.min_bias_jitter_rad_s);
    const math::Vec3 pull = (1.0 - a) * bmean;
    fill_noise();
    const double* z = noise_.data();
    for (int i = 0; i < n_; ++i) {
        const double dx = sq * z[i], dy = sq * z[n_ + i], dz = sq * z[2 * n_ + i];
        double dw, s;
        small_exp(dx, dy, dz, dw, s);
        // δq ⊗ q_i: the jitter is a small rotation in the earth frame.
        const Q4 q = mul_unit({dw, s * dx, s * dy, s * dz}, {qw_[i], qx_[i], qy_[i], qz_[i]});
        qw_[i] = q.w;
        qx_[i] = q.x;
        qy_[i] = q.y;
        qz_[i] = q.z;
        bx_[i] = a * bx_[i] + pull.x() + sb.x() * z[3 * n_ + i];
        by_[i] = a * by_[i] + pull.y() + sb.y() * z[4 * n_ + i];
        bz_[i] = a * bz_[i] + pull.z() + sb.z() * z[5 * n_ + i];
    }
}

void ParticleFilter::update(const ImuSample& sample) {
    const double dt = clock_.step_s(sample.t_us);
    const math::Vec3 gyro = math::to_vec3(sample.gyro_rad_s);
    if (!gyro.allFinite()) {
        ++state_.rejected_measurements;
        return;
    }
    math::Quat q_m;
    const bool have_m = measure(sample, q_m);
    if (!state_.initialised) {
        if (have_m)
            initialise(q_m);
        else
            ++state_.rejected_measurements;
        return;
    }
    if (dt > 0.0) predict(gyro, dt);
    if (!have_m) {
        ++state_.rejected_measurements;
        estimate();
        return;
    }
    state_.q_measured = q_m;
    if (!weigh(q_m)) {
        ++state_.reinitialisations;
        initialise(q_m);
        return;
    }
    estimate();
    if (state_.n_eff < params_.resample_frac * n_) {
        resample();
        regularise();
        state_.n_eff = n_;
    }
}

}  // namespace mocap::filter
