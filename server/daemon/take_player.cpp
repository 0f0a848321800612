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
        time_shift_us_ = clock_.now_us() - first_received_us_;
    } else {
        // One SYNC period (of the subject with the most SYNCs) after the last sample of the
        // previous pass; each subject's SYNCs move on by its own count.
        std::uint64_t most = 1;
        for (const auto& [subject, e] : syncs_) {
            most = std::max(most, e.last - e.first + 1);
            sync_shift_[subject] += e.last - e.first + 1;
        }
        const std::int64_t span = last_received_us_ - first_received_us_;
        const std::int64_t period = most > 1 ? span / static_cast<std::int64_t>(most - 1) : 10'000;
        time_shift_us_ += span + std::max<std::int64_t>(period, 1);
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
            const auto [e, fresh] = syncs_.try_emplace(s.subject_id, SyncExtent{s.sync, s.sync});
            if (!fresh) {
                e->second.first = std::min(e->second.first, s.sync);
                e->second.last = std::max(e->second.last, s.sync);
            }
        }
        s.imu.t_us += time_shift_us_;
        if (s.times.sink_send_us != 0) s.times.sink_send_us += time_shift_us_;
        s.times.received_us = clock_.now_us();
        if (const auto shift = sync_shift_.find(s.subject_id); shift != sync_shift_.end()) s.sync += shift->second;
        route_(s);
        samples_.add();
        (void)read_next();
    }
    schedule();
}

}  // namespace mocap::daemon
