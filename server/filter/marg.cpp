#include "filter/marg.hpp"

#include <cmath>

#include "filter/attitude_solver.hpp"

namespace mocap::filter {

MargReading read_marg(const ImuSample& sample) {
    MargReading r;
    r.accel_m_s2 = math::to_vec3(sample.accel_m_s2);
    r.mag_ut = math::to_vec3(sample.mag_ut);
    r.accel_ok = r.accel_m_s2.squaredNorm() > 0.0 && r.accel_m_s2.allFinite();
    r.mag_ok = sample.has_mag() && r.mag_ut.squaredNorm() > 0.0 && r.mag_ut.allFinite();
    return r;
}

math::Quat attitude_from_accel_mag(const math::Vec3& accel_m_s2, const math::Vec3& mag_ut, bool use_mag) {
    if (use_mag) {
        // Only the horizontal direction of the reference matters to TRIAD: north.
        const AttitudeSolution sol = solve_triad(accel_m_s2, mag_ut, math::Vec3::UnitY());
        if (sol.ok()) return sol.q_earth_sensor;
    }
    // Shortest rotation taking the measured up direction to earth z: zero heading.
    return tilt_to_vertical(accel_m_s2.normalized());
}

math::Quat tilt_to_vertical(const math::Vec3& u) {
    const double qw = std::sqrt((u.z() + 1.0) / 2.0);
    if (qw > 1e-6) return math::Quat(qw, 0.5 * u.y() / qw, -0.5 * u.x() / qw, 0.0);
    return math::Quat(0.0, 1.0, 0.0, 0.0);  // u points down: any horizontal axis, 180°
}

}  // namespace mocap::filter
