#include "daemon/play_pacer.hpp"

#include <algorithm>
#include <limits>

namespace mocap::daemon {

namespace {

constexpr std::int64_t kMax = std::numeric_limits<std::int64_t>::max();
constexpr std::int64_t kMin = std::numeric_limits<std::int64_t>::min();

// The file's values are untrusted: a difference of two of them may not fit.
std::int64_t sat_sub(std::int64_t a, std::int64_t b) {
    std::int64_t r = 0;
    if (__builtin_sub_overflow(a, b, &r)) return b < 0 ? kMax : kMin;
    return r;
}

std::int64_t sat_add(std::int64_t a, std::int64_t b) {
    std::int64_t r = 0;
    if (__builtin_add_overflow(a, b, &r)) return b < 0 ? kMin : kMax;
    return r;
}

}  // namespace

PlayPacer::PlayPacer(std::int64_t max_gap_us) : max_gap_us_(std::max<std::int64_t>(max_gap_us, 1)) {}

void PlayPacer::restart() {
    end_us_ = 0;
    for (auto& [id, p] : subjects_)
        p.placed = false;
}

std::int64_t PlayPacer::period_of(const Subject& p) const {
    if (p.n_periods == 0) return kDefaultSyncPeriodUs;
    std::array<std::int64_t, kPeriods> v = p.periods;
    const auto mid = v.begin() + static_cast<std::ptrdiff_t>(p.n_periods / 2);
    std::nth_element(v.begin(), mid, v.begin() + static_cast<std::ptrdiff_t>(p.n_periods));
    return *mid;
}

std::int64_t PlayPacer::period_us() const {
    std::int64_t longest = 0;
    for (const auto& [id, p] : subjects_)
        if (p.placed) longest = std::max(longest, period_of(p));
    return longest > 0 ? longest : kDefaultSyncPeriodUs;
}

PlayPacer::Due PlayPacer::next(const SegmentSample& s) {
    Subject& p = subjects_[s.subject_id];
    if (!p.placed) {
        // Its first sample in this pass: it joins the take where the take is now.
        p.placed = true;
        p.sync = s.sync;
        p.t_us = s.imu.t_us;
        p.received_us = s.times.received_us;
        p.offset_us = end_us_;
        return {p.offset_us, Clamp::kNone, 0};
    }
    const std::int64_t received_step = sat_sub(s.times.received_us, p.received_us);
    p.received_us = s.times.received_us;
    Due due;
    std::int64_t step = 0;
    if (s.sync == 0) {
        // No SYNC to pace by: the receive time, within [0, max_gap].
        step = std::clamp<std::int64_t>(received_step, 0, max_gap_us_);
        if (received_step < 0) due.clamp = Clamp::kBackward;
        if (received_step > max_gap_us_) due.clamp = Clamp::kGap;
        due.step_us = received_step;
    } else if (s.sync > p.sync) {
        const std::uint64_t k = s.sync - p.sync;
        const std::int64_t t_step = sat_sub(s.imu.t_us, p.t_us);
        p.sync = s.sync;
        p.t_us = s.imu.t_us;
        if (k <= static_cast<std::uint64_t>(max_gap_us_) && t_step > 0 && t_step <= max_gap_us_) {
            const std::int64_t candidate = t_step / static_cast<std::int64_t>(k);
            if (candidate > 0) {
                p.periods[p.next_period] = candidate;
                p.next_period = (p.next_period + 1) % kPeriods;
                p.n_periods = std::min(p.n_periods + 1, kPeriods);
            }
        }
        const std::int64_t period = period_of(p);
        // k periods, at most max_gap (k * period may not fit either).
        const bool too_long = k > static_cast<std::uint64_t>(max_gap_us_ / period);
        const std::int64_t by_sync = too_long ? max_gap_us_ : static_cast<std::int64_t>(k) * period;
        // The recorded step where the SYNC counter bears it out (a live sink's late or early
        // SYNCs are played as they came); otherwise the SYNC's.
        const bool plausible = t_step > 0 && t_step <= max_gap_us_ && (too_long || t_step <= 4 * by_sync);
        step = plausible ? t_step : by_sync;
        if (t_step < 0 || received_step < -max_gap_us_) {
            due.clamp = Clamp::kBackward;
            due.step_us = t_step < 0 ? t_step : received_step;
        } else if ((!plausible && t_step > by_sync) || received_step > max_gap_us_) {
            due.clamp = Clamp::kGap;
            due.step_us = !plausible && t_step > by_sync ? t_step : received_step;
        }
    } else if (received_step > max_gap_us_ || received_step < -max_gap_us_) {
        // Another segment of the instant (or a late one): due with its instant whatever its
        // receive time says.
        due.clamp = received_step > 0 ? Clamp::kGap : Clamp::kBackward;
        due.step_us = received_step;
    }
    p.offset_us = sat_add(p.offset_us, step);
    end_us_ = std::max(end_us_, p.offset_us);
    due.offset_us = p.offset_us;
    if (due.clamp == Clamp::kNone) due.step_us = 0;
    return due;
}

}  // namespace mocap::daemon
