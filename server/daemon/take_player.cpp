#include "daemon/take_player.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <utility>

#include "core/metrics_registry.hpp"

namespace mocap::daemon {

namespace {
/// Samples handed on per timer run at most: a take recorded in bursts cannot hold the ingest
/// thread for long (the rest are due already and follow at once).
constexpr int kBurst = 4096;
}  // namespace

TakePlayer::TakePlayer(asio::io_context& io, PlayOptions options, const Clock& clock, Route route)
    : io_(io), options_(std::move(options)), clock_(clock), route_(std::move(route)), timer_(io) {
    group_.add("samples", samples_);
    group_.add("passes", passes_);
    group_.add("errors", errors_);
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
    if (!read_next()) return true;  // an empty take: have_next_ stays false
    if (!have_first_) {
        have_first_ = true;
        first_received_us_ = last_received_us_ = next_.times.received_us;
        first_sync_ = last_sync_ = next_.sync;
        time_shift_us_ = clock_.now_us() - first_received_us_;
        sync_shift_ = 0;
    } else {
        // One SYNC period after the last sample of the previous pass.
        const std::uint64_t syncs = last_sync_ - first_sync_ + 1;
        const std::int64_t span = last_received_us_ - first_received_us_;
        const std::int64_t period = syncs > 1 ? span / static_cast<std::int64_t>(syncs - 1) : 10'000;
        time_shift_us_ += span + period;
        sync_shift_ += syncs;
    }
    return true;
}

bool TakePlayer::read_next() {
    for (;;) {
        std::string error;
        const int r = reader_.next(next_, &error);
        if (r == 1) {
            have_next_ = true;
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

std::int64_t TakePlayer::due_us(const SegmentSample& s) const {
    return s.times.received_us + time_shift_us_;
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
    const std::int64_t wait = due_us(next_) - clock_.now_us();
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
    for (int n = 0; have_next_ && n < kBurst && due_us(next_) <= now; ++n) {
        SegmentSample s = next_;
        if (passes_.value() == 1) {
            last_received_us_ = std::max(last_received_us_, s.times.received_us);
            last_sync_ = std::max(last_sync_, s.sync);
        }
        s.imu.t_us += time_shift_us_;
        if (s.times.sink_send_us != 0) s.times.sink_send_us += time_shift_us_;
        s.times.received_us = clock_.now_us();
        s.sync += sync_shift_;
        route_(s);
        samples_.add();
        (void)read_next();
    }
    schedule();
}

}  // namespace mocap::daemon
