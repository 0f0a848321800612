#include "fusion/chain_smoother.hpp"

#include <algorithm>
#include <cmath>

#include "fusion/hinge_axis_estimator.hpp"

namespace mocap::fusion {
namespace {

/// The hinges' axes from the whole take: the estimator's ring spread evenly over the take's
/// informative samples rather than holding the last ones.
std::vector<JointDef> with_take_axes(std::size_t ns, std::span<const JointDef> joints, const ChainParams& params,
                                     std::span<const std::int64_t> t_us, std::span<const SegmentInput> in) {
    std::vector<JointDef> defs(joints.begin(), joints.end());
    const std::size_t rows = t_us.size();
    if (rows < 2) return defs;
    const double take_s = static_cast<double>(t_us.back() - t_us.front()) * 1e-6;
    for (JointDef& d : defs) {
        if (d.type != JointType::kHinge || (d.axes_known && !d.estimate_axes)) continue;
        HingeAxisParams p = params.axis;
        p.capacity = std::max<std::size_t>(p.capacity, 2000);
        p.sample_spacing_s = std::max(p.sample_spacing_s, take_s / static_cast<double>(p.capacity));
        p.solve_interval_s = 1e12;  // once, below
        HingeAxisEstimator est(p);
        const auto ip = static_cast<std::size_t>(d.parent), ic = static_cast<std::size_t>(d.child);
        for (std::size_t k = 0; k < rows; ++k) {
            const SegmentInput& a = in[k * ns + ip];
            const SegmentInput& b = in[k * ns + ic];
            if (a.fresh && b.fresh) est.add(t_us[k], a.gyro_rad_s, b.gyro_rad_s, a.q6, b.q6);
        }
        if (est.samples() < p.min_samples) continue;  // too little motion to trust: the passes keep trying
        est.solve();
        if (!est.ready()) continue;  // the passes keep trying on their own
        d.axis_parent = est.axis_parent();
        d.axis_child = est.axis_child();
        d.axes_known = true;
        d.estimate_axes = false;
    }
    return defs;
}

struct Pass {
    std::vector<double> delta, sigma;  // rows × joints
    std::vector<HeadingSource> source;
    std::vector<char> known;
};

Pass run_pass(std::size_t ns, std::span<const JointDef> defs, const ChainParams& params,
              std::span<const std::int64_t> t_us, std::span<const SegmentInput> in, bool forward,
              std::vector<JointStatus>* end_status) {
    const std::size_t rows = t_us.size(), nj = defs.size();
    Pass pass{std::vector<double>(rows * nj), std::vector<double>(rows * nj), std::vector<HeadingSource>(rows * nj),
              std::vector<char>(rows * nj)};
    ChainEstimator est(ns, defs, params);
    std::vector<SegmentInput> step(ns);
    std::vector<SegmentOutput> out(ns);
    for (std::size_t n = 0; n < rows; ++n) {
        const std::size_t k = forward ? n : rows - 1 - n;
        // Backwards: time runs from the last instant, and every rate is reversed.
        const std::int64_t t = forward ? t_us[k] : t_us.back() + (t_us.back() - t_us[k]);
        for (std::size_t s = 0; s < ns; ++s) {
            step[s] = in[k * ns + s];
            if (!forward) step[s].gyro_rad_s = -step[s].gyro_rad_s;
        }
        est.update(t, step, out);
        for (std::size_t j = 0; j < nj; ++j) {
            const JointStatus st = est.status(j);
            pass.delta[k * nj + j] = st.delta_rad;
            pass.sigma[k * nj + j] = st.sigma_rad;
            pass.source[k * nj + j] = st.source;
            pass.known[k * nj + j] = static_cast<char>(st.initialised);
        }
    }
    if (end_status) {
        for (std::size_t j = 0; j < nj; ++j)
            end_status->push_back(est.status(j));
    }
    return pass;
}

}  // namespace

ChainSmoothResult smooth_chain(std::size_t segment_count, std::span<const JointDef> joints, const ChainParams& params,
                               std::span<const std::int64_t> t_us, std::span<const SegmentInput> in) {
    const std::size_t ns = segment_count, nj = joints.size(), rows = t_us.size();
    ChainSmoothResult r;
    r.out.resize(rows * ns);
    r.delta_rad.resize(rows * nj);
    r.sigma_rad.resize(rows * nj);
    const std::vector<JointDef> defs = with_take_axes(ns, joints, params, t_us, in);
    const Pass fwd = run_pass(ns, defs, params, t_us, in, true, &r.joints);
    const Pass bwd = run_pass(ns, defs, params, t_us, in, false, nullptr);
    ChainEstimator composer(ns, defs, params);
    std::vector<JointHeading> headings(nj);
    for (std::size_t k = 0; k < rows; ++k) {
        for (std::size_t j = 0; j < nj; ++j) {
            const std::size_t i = k * nj + j;
            JointHeading& h = headings[j];
            h.known = fwd.known[i] || bwd.known[i];
            if (fwd.known[i] && bwd.known[i]) {
                const double vf = fwd.sigma[i] * fwd.sigma[i], vb = bwd.sigma[i] * bwd.sigma[i];
                h.delta_rad = math::wrap_pi(fwd.delta[i] + vf / (vf + vb) * math::wrap_pi(bwd.delta[i] - fwd.delta[i]));
                r.sigma_rad[i] = std::sqrt(vf * vb / (vf + vb));
                h.source = vf <= vb ? fwd.source[i] : bwd.source[i];
            } else {
                const Pass& only = fwd.known[i] ? fwd : bwd;
                h.delta_rad = only.delta[i];
                r.sigma_rad[i] = only.sigma[i];
                h.source = only.source[i];
            }
            r.delta_rad[i] = h.delta_rad;
        }
        composer.compose(in.subspan(k * ns, ns), headings, std::span<SegmentOutput>(r.out.data() + k * ns, ns));
    }
    return r;
}

}  // namespace mocap::fusion
