#include "filter/particle_filter.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <numbers>

#include <Eigen/Cholesky>

#include "filter/marg.hpp"
#include "math/markley_average.hpp"

namespace mocap::filter {

namespace {

// The detection as the particle filter was tuned with (docs/accuracy.md, "Particle filter
// (pf)"): the default filter with its earlier, slower bias learning in motion. The default's
// faster one moves the detector's attitude, and with it its field checks, and costs pf
// 0.07° on the six BROAD recordings' mean (0.35° on the fast combined one). The magnetometer
// lag is not taken out either: the detector's checks would then judge a field other than the
// one the particles weigh, which cost pf 0.12° on that mean (0.22° on the fast ones).
MocapFilterParams detector_params() {
    MocapFilterParams p;
    p.bias_sigma_motion_deg_s = 0.1;
    p.mag_delay_s = 0.0;
    return p;
}

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
    : params_(params),
      n_(std::clamp(params.particles, 1, 65536)),
      detector_(detector_params()),
      clock_(params.max_step_s) {
    for (auto* v : {&qw_, &qx_, &qy_, &qz_, &bx_, &by_, &bz_, &w_, &cost_, &qw_tmp_, &qx_tmp_, &qy_tmp_, &qz_tmp_,
                    &bx_tmp_, &by_tmp_, &bz_tmp_})
        v->assign(static_cast<std::size_t>(n_), 0.0);
    noise_.assign(6 * static_cast<std::size_t>(n_), 0.0);
    reset();
}

void ParticleFilter::reset() {
    state_ = ParticleFilterState{};
    clock_.reset();
    detector_.reset();
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

FilterDiagnostics ParticleFilter::diagnostics() const {
    return params_.detect ? detector_.diagnostics() : FilterDiagnostics{};
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
    state_.q_earth_sensor = math::canonical(q_m);
    estimate();
    state_.n_eff = n_;
}

void ParticleFilter::predict(const math::Vec3& gyro, double dt) {
    const double h = 0.5 * dt;
    // Densities: the angle noise of one step has σ = gyro_noise·√dt, the bias step
    // bias_walk·√dt, so a second of propagation spreads the cloud equally at any rate.
    const double gs = 0.5 * params_.gyro_noise * std::sqrt(dt);
    const double bs = params_.bias_walk * std::sqrt(dt);
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

bool ParticleFilter::weigh(const Measurement& z, bool replace) {
    // Tilt: the specific force over g against each particle's up direction in the sensor
    // frame, u_i = R_iᵀ e_z; the residual is linear in the linear acceleration, so zero-mean
    // accelerations average out over the filter's memory. One sample's σ is meas / √dt.
    const double dt = state_.dt_s;
    const double kt = 0.5 * dt / (params_.meas_tilt * params_.meas_tilt);
    const double ax = z.up_g.x(), ay = z.up_g.y(), az = z.up_g.z();
    // Heading: e = q_i ⊗ q_h*, whose z component is sin(θ/2) of the heading difference in the
    // earth frame; ½ (2 e_z)² / σ² = 2 e_z² dt / meas².
    const math::Quat& h = z.q_heading;
    const double pw = h.w(), px = -h.x(), py = -h.y(), pz = -h.z();
    const double kh = z.use_heading ? 2.0 * dt / (params_.meas_heading * params_.meas_heading) : 0.0;
    double cmin = std::numeric_limits<double>::infinity();
    for (int i = 0; i < n_; ++i) {
        const double qw = qw_[i], qx = qx_[i], qy = qy_[i], qz = qz_[i];
        const double ux = 2.0 * (qx * qz - qw * qy) - ax;
        const double uy = 2.0 * (qy * qz + qw * qx) - ay;
        const double uz = qw * qw - qx * qx - qy * qy + qz * qz - az;
        const double ez = qw * pz + qx * py - qy * px + qz * pw;
        cost_[i] = kt * (ux * ux + uy * uy + uz * uz) + kh * ez * ez;
    }
    if (z.rest_gyro) {
        // At rest the gyro reads the bias plus white noise of density gyro_noise.
        const double kb = 0.5 * dt / (params_.gyro_noise * params_.gyro_noise);
        const double gx = z.rest_gyro->x(), gy = z.rest_gyro->y(), gz = z.rest_gyro->z();
        for (int i = 0; i < n_; ++i) {
            const double dx = bx_[i] - gx, dy = by_[i] - gy, dz = bz_[i] - gz;
            cost_[i] += kb * (dx * dx + dy * dy + dz * dz);
        }
    }
    for (int i = 0; i < n_; ++i)
        cmin = std::min(cmin, cost_[i]);
    // Subtracting the best cost keeps the largest likelihood at 1: no underflow of them all.
    double sum = 0.0;
    for (int i = 0; i < n_; ++i) {
        w_[i] = (replace ? 1.0 : w_[i]) * exp_nonpositive(cmin - cost_[i]);
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
    // Chart around the estimate m: x_i = (v_i, b_i) with v_i = vec(q_i ⊗ m*) taken with
    // w >= 0 (earth-frame half-angle vector), and q_i = [√(1 − |v_i|²), v_i] ⊗ m back.
    using Vec6 = Eigen::Matrix<double, 6, 1>;
    using Mat6 = Eigen::Matrix<double, 6, 6>;
    const math::Quat& m = state_.q_earth_sensor;
    const double mw = m.w(), mx = -m.x(), my = -m.y(), mz = -m.z();  // m*
    double* __restrict vx = qx_tmp_.data();                          // the chart coordinates, in the spare arrays
    double* __restrict vy = qy_tmp_.data();
    double* __restrict vz = qz_tmp_.data();
    Vec6 sum = Vec6::Zero();
    Mat6 sq = Mat6::Zero();
    for (int i = 0; i < n_; ++i) {
        const double qw = qw_[i], qx = qx_[i], qy = qy_[i], qz = qz_[i];
        const double ew = qw * mw - qx * mx - qy * my - qz * mz;
        const double sgn = ew < 0.0 ? -1.0 : 1.0;
        vx[i] = sgn * (qw * mx + qx * mw + qy * mz - qz * my);
        vy[i] = sgn * (qw * my - qx * mz + qy * mw + qz * mx);
        vz[i] = sgn * (qw * mz + qx * my - qy * mx + qz * mw);
        const Vec6 x(vx[i], vy[i], vz[i], bx_[i], by_[i], bz_[i]);
        sum += x;
        sq.selfadjointView<Eigen::Lower>().rankUpdate(x);
    }
    const double inv_n = 1.0 / n_;
    const Vec6 mean = sum * inv_n;
    Mat6 cov = sq.selfadjointView<Eigen::Lower>();
    cov = cov * inv_n - mean * mean.transpose();
    // A cloud resampled from very few particles has a (near) singular covariance; a tiny
    // diagonal keeps the factor defined and moves nothing measurably.
    cov.diagonal().array() += 1e-18;
    const double h = std::clamp(params_.reg_h, 0.0, 0.999);
    const double a = std::sqrt(1.0 - h * h);
    // The one-pass covariance can lose its positive definiteness to rounding (a collapsed
    // cloud around a large bias): then the kernel falls back to the diagonal, never to a
    // half-factored matrix.
    const Eigen::LLT<Mat6> llt(cov);
    Mat6 l;
    if (llt.info() == Eigen::Success) {
        l = h * llt.matrixL().toDenseMatrix();
    } else {
        l = (h * cov.diagonal().cwiseMax(0.0).cwiseSqrt()).asDiagonal();
    }
    const Vec6 pull = (1.0 - a) * mean;
    fill_noise();
    const double* z = noise_.data();
    for (int i = 0; i < n_; ++i) {
        const Vec6 zi(z[i], z[n_ + i], z[2 * n_ + i], z[3 * n_ + i], z[4 * n_ + i], z[5 * n_ + i]);
        const Vec6 x =
            a * Vec6(vx[i], vy[i], vz[i], bx_[i], by_[i], bz_[i]) + pull + l.triangularView<Eigen::Lower>() * zi;
        double v2 = x.head<3>().squaredNorm();
        const double shrink = v2 > 1.0 ? 1.0 / std::sqrt(v2) : 1.0;
        v2 = std::min(v2, 1.0);
        const Q4 q =
            mul_unit({std::sqrt(1.0 - v2), shrink * x[0], shrink * x[1], shrink * x[2]}, {m.w(), m.x(), m.y(), m.z()});
        qw_[i] = q.w;
        qx_[i] = q.x;
        qy_[i] = q.y;
        qz_[i] = q.z;
        bx_[i] = x[3];
        by_[i] = x[4];
        bz_[i] = x[5];
    }
}

void ParticleFilter::update(const ImuSample& sample) {
    const double dt = clock_.step_s(sample.t_us);
    if (dt > 0.0) state_.dt_s = dt;
    const math::Vec3 gyro = math::to_vec3(sample.gyro_rad_s);
    if (!gyro.allFinite()) {
        ++state_.rejected_measurements;
        return;
    }
    if (params_.detect) detector_.update(sample);
    MargReading r = read_marg(sample);
    if (params_.detect && r.mag_ok) {
        // A field offset fixed to the sensor (a magnet it carries), as far as the detector
        // has learned it; what it cannot explain, it flags.
        const FilterDiagnostics d = detector_.diagnostics();
        r.mag_ut -= d.mag_offset_weight * d.mag_offset_ut;
    }
    // Only the horizontal direction of the reference matters to TRIAD.
    const auto triad = [&r](AttitudeSolution& s) {
        if (!r.accel_ok || !r.mag_ok) return false;
        s = solve_triad(r.accel_m_s2, r.mag_ut, field_direction_enu(0.0), LmaParams{});
        return s.ok();
    };
    AttitudeSolution s;
    if (!state_.initialised) {
        if (triad(s))
            initialise(s.q_earth_sensor);
        else
            ++state_.rejected_measurements;
        return;
    }
    if (dt > 0.0) predict(gyro, dt);
    if (!r.accel_ok || state_.dt_s == 0.0) {
        ++state_.rejected_measurements;
        estimate();
        return;
    }
    // Heading: the horizontal field seen through the estimate's tilt, not through the
    // sample's own (TRIAD's), which has every linear acceleration of the sample in it; while
    // the detector rejects the field, no heading term.
    Measurement z;
    z.up_g = r.accel_m_s2 / params_.gravity_m_s2;
    z.use_heading = r.mag_ok && !(params_.detect && detector_.mag_rejected());
    z.rest_gyro = params_.detect && detector_.state().rest_detected ? &gyro : nullptr;
    z.q_heading = state_.q_earth_sensor;
    if (z.use_heading) {
        // The angle of the horizontal field, or, when the detector finds the field noise too
        // large to see a disturbance (noise near the field's size: the angle of each reading
        // wraps and is pulled towards 0), its cross product with north over the detector's
        // vector mean of the horizontal field, which stays unbiased. (That form everywhere
        // cost 0.6° on the stationary-magnet recording.)
        const math::Vec3 m_e = math::rotate(state_.q_earth_sensor, r.mag_ut);
        const double h_ref = detector_.state().mag_horizontal_lp.norm();
        const bool noisy = params_.detect && detector_.state().mag_guard_blind && m_e.y() > 0.0 && h_ref > 0.0;
        const double half_pi = 0.5 * std::numbers::pi;
        const double hd = 0.5 * (noisy ? std::clamp(m_e.x() / h_ref, -half_pi, half_pi) : std::atan2(m_e.x(), m_e.y()));
        z.q_heading = math::Quat(std::cos(hd), 0.0, 0.0, std::sin(hd)) * z.q_heading;
    } else if (r.mag_ok) {
        ++state_.heading_gated;
    }
    if (!weigh(z, false)) {
        // Every particle is far off (the likelihood underflowed): start again around this
        // sample's attitude, or the estimate, with the initial spreads.
        ++state_.reinitialisations;
        initialise(triad(s) ? s.q_earth_sensor : state_.q_earth_sensor);
        return;
    }
    estimate();
    if (state_.n_eff < params_.resample_frac * n_) {
        resample();
        regularise();
        // Step 6 of the method: the moved particles are weighted by this measurement.
        if (!weigh(z, true)) {
            std::fill(w_.begin(), w_.end(), 1.0 / n_);
            state_.n_eff = n_;
        }
        estimate();
    }
}

}  // namespace mocap::filter
