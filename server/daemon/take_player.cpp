#include "daemon/take_player.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <limits>
#include <utility>

#include "core/metrics_registry.hpp"

namespace mocap::daemon {

namespace {
/// Samples handed on per timer run at most: a take recorded in bursts cannot hold the ingest
/// thread for long (the rest are due already and follow at once).
constexpr int kBurst = 4096;

std::int64_t add_saturated(std::int64_t a, std::int64_t b) {
    std::int64_t r = 0;
    if (__builtin_add_overflow(a, b, &r))
        return b < 0 ? std::numeric_limits<std::int64_t>::min() : std::numeric_limits<std::int64_t>::max();
    return r;
}

std::int64_t max_gap_us(double max_gap_s) {
    // A setting, so also bounded here: between 1 ms and a day.
    return static_cast<std::int64_t>(std::clamp(max_gap_s, 1e-3, 86'400.0) * 1e6);
}
}  // namespace

TakePlayer::TakePlayer(asio::io_context& io, PlayOptions options, const Clock& clock, Route route)
    : io_(io),
      options_(std::move(options)),
      clock_(clock),
      route_(std::move(route)),
      timer_(io),
      pacer_(max_gap_us(options_.max_gap_s)) {
    group_.add("samples", samples_);
    group_.add("passes", passes_);
    group_.add("errors", errors_);
    group_.add("gaps_clamped", gaps_clamped_);
    group_.add("steps_back", steps_back_);
}

void TakePlayer::register_metrics(MetricsRegistry& registry) const {
    registry.add(group_);
}

bool TakePlayer::start(std::string* error) {
    if (options_.files.empty()) {
        *error = "play: no raw recording given";
        return false;
    }
    for (const auto& f : options_.files) {
        serve::RawRecordingReader probe;
        if (!probe.open(f, error)) {
            *error = "play: " + *error;
            return false;
        }
    }
    if (!begin_pass(error)) return false;
    if (!have_next_) {
        *error = "play: " + options_.files.front() + " holds no sample";
        return false;
    }
    asio::post(io_, [this] { schedule(); });
    return true;
}

bool TakePlayer::begin_pass(std::string* error) {
    file_ = 0;
    if (!reader_.open(options_.files[file_], error)) return false;
    passes_.add();
    if (!have_first_) {
        have_first_ = true;
        pass_start_us_ = clock_.now_us();
    } else {
        // One SYNC period after the last sample of the previous pass, and never sooner than
        // kMinPassUs after its start; each subject's SYNCs move on by its own count.
        const std::int64_t length = std::max(add_saturated(pacer_.end_us(), pacer_.period_us()), kMinPassUs);
        pass_start_us_ = add_saturated(pass_start_us_, length);
        for (const auto& [subject, e] : syncs_) {
            auto& shift = sync_shift_[subject];
            const std::uint64_t span = e.last - e.first + 1;
            shift = shift > std::numeric_limits<std::uint64_t>::max() - span ? shift : shift + span;
        }
    }
    pacer_.restart();
    (void)read_next();  // an empty take: have_next_ stays false
    return true;
}

bool TakePlayer::read_next() {
    for (;;) {
        std::string error;
        const int r = reader_.next(next_, &error);
        if (r == 1) {
            have_next_ = true;
            const PlayPacer::Due due = pacer_.next(next_);
            report(due);
            next_due_us_ = add_saturated(pass_start_us_, due.offset_us);
            return true;
        }
        if (r < 0) {
            errors_.add();
            spdlog::error("play: {}: {}; the pass ends here", options_.files[file_], error);
            have_next_ = false;
            return false;
        }
        if (reader_.truncated()) spdlog::warn("play: {}: {}", options_.files[file_], reader_.truncation());
        if (++file_ >= options_.files.size()) {
            have_next_ = false;
            return false;
        }
        if (!reader_.open(options_.files[file_], &error)) {
            errors_.add();
            spdlog::error("play: {}; the pass ends here", error);
            have_next_ = false;
            return false;
        }
    }
}

void TakePlayer::report(const PlayPacer::Due& due) {
    const double step_s = static_cast<double>(due.step_us) / 1e6;
    const double max_s = static_cast<double>(pacer_.max_gap_us()) / 1e6;
    if (due.clamp == PlayPacer::Clamp::kGap) {
        gaps_clamped_.add();
        if (!std::exchange(logged_gap_, true))
            spdlog::warn(
                "play: {}: the recorded time jumps {:.3f} s ahead at sample {}; a gap is played as the SYNC "
                "counter says and never longer than {:.3f} s (counted in play.gaps_clamped, logged once)",
                options_.files[file_], step_s, reader_.samples_read(), max_s);
    } else if (due.clamp == PlayPacer::Clamp::kBackward) {
        steps_back_.add();
        if (!std::exchange(logged_back_, true))
            spdlog::warn(
                "play: {}: the recorded time steps {:.3f} s back at sample {}; played as the SYNC counter says "
                "(or with no wait where there is none) (counted in play.steps_back, logged once)",
                options_.files[file_], -step_s, reader_.samples_read());
    }
}

void TakePlayer::schedule() {
    if (!have_next_) {
        if (!options_.loop) {
            if (!ended_) spdlog::info("play: the take ended after {} samples; still serving", samples_.value());
            ended_ = true;
            return;
        }
        std::string error;
        if (!begin_pass(&error) || !have_next_) {
            errors_.add();
            ended_ = true;
            spdlog::error("play: cannot start the take again: {}", error.empty() ? "no sample" : error);
            return;
        }
    }
    std::int64_t wait = next_due_us_ - clock_.now_us();
    // No wait is longer than a gap or a pass: a longer one means the host's clock stepped
    // back, and the take goes on from now instead of freezing for that long.
    if (const std::int64_t longest = std::max(pacer_.max_gap_us(), kMinPassUs); wait > longest) {
        pass_start_us_ -= wait - longest;
        next_due_us_ -= wait - longest;
        wait = longest;
    }
    if (wait <= 0) {
        asio::post(io_, [this] { play_due(); });
        return;
    }
    timer_.expires_after(std::chrono::microseconds(wait));
    timer_.async_wait([this](const boost::system::error_code& ec) {
        if (!ec) play_due();
    });
}

void TakePlayer::play_due() {
    const std::int64_t now = clock_.now_us();
    for (int n = 0; have_next_ && n < kBurst && next_due_us_ <= now; ++n) {
        SegmentSample s = next_;
        if (passes_.value() == 1) {
            const auto [e, fresh] = syncs_.try_emplace(s.subject_id, SyncExtent{s.sync, s.sync});
            if (!fresh) {
                e->second.first = std::min(e->second.first, s.sync);
                e->second.last = std::max(e->second.last, s.sync);
            }
        }
        // The sample instant is when it is due; the sink sent it as long before it was
        // received as it did when recorded (within max_gap), so ingest latency reads true.
        if (s.times.sink_send_us != 0) {
            std::int64_t before = 0;
            if (__builtin_sub_overflow(s.times.received_us, s.times.sink_send_us, &before)) before = 0;
            s.times.sink_send_us = next_due_us_ - std::clamp<std::int64_t>(before, 0, pacer_.max_gap_us());
        }
        s.imu.t_us = next_due_us_;
        s.times.received_us = clock_.now_us();
        if (const auto shift = sync_shift_.find(s.subject_id); shift != sync_shift_.end()) s.sync += shift->second;
        route_(s);
        samples_.add();
        (void)read_next();
    }
    schedule();
}

}  // namespace mocap::daemon
