// pose_broadcaster.cpp — encode once, hand over to each serve thread, fan out there.
#include "serve/pose_broadcaster.hpp"

#include <algorithm>
#include <chrono>

#include "serve/client_session.hpp"
#include "serve/subscription_index.hpp"

namespace mocap::serve {

PoseBroadcaster::PoseBroadcaster(const std::vector<asio::io_context*>& lanes, std::size_t backlog_frames,
                                 std::function<std::int64_t()> wall_clock_us, ServeCounters& counters)
    : indexes_(lanes.size()),
      backlog_(lanes, backlog_frames, [this](std::size_t lane, const EncodedFrame& frame) { drain(lane, frame); }),
      wall_clock_us_(std::move(wall_clock_us)),
      counters_(counters) {
    if (!wall_clock_us_) {
        wall_clock_us_ = [] {
            return std::chrono::duration_cast<std::chrono::microseconds>(
                       std::chrono::system_clock::now().time_since_epoch())
                .count();
        };
    }
}

PoseBroadcaster::~PoseBroadcaster() = default;

void PoseBroadcaster::publish(const SubjectFrame& frame, const skeleton::SkeletonPose& pose) {
    if (stopped_.load(std::memory_order_acquire)) return;
    counters_.frames_published.add();
    if (all_subject_users_.load(std::memory_order_relaxed) == 0 &&
        subject_interest_[frame.subject_id % kInterestSlots].load(std::memory_order_relaxed) == 0) {
        return;  // nobody watches this subject
    }
    EncodedFrame encoded;
    encoded.subject_id = frame.subject_id;
    encoded.sync = frame.sync;
    bool any = false;
    {
        std::lock_guard lock(encode_mutex_);
        const std::int64_t now_us = wall_clock_us_();
        for (std::uint32_t f = 1; f < kFieldCombinations; ++f) {
            if (field_users_[f].load(std::memory_order_relaxed) == 0) continue;
            encoded.by_fields[f] = encoder_.encode_frame(frame, pose, f, now_us);
            counters_.frames_encoded.add();
            any = true;
        }
    }
    if (!any) return;  // nobody subscribed: nothing to send

    // A lane that refuses is not keeping up at all (not a slow client: those drop in their
    // own queues). Dropping there keeps publish() bounded.
    if (const std::size_t refused = backlog_.push(encoded); refused > 0) counters_.backlog_dropped.add(refused);
}

void PoseBroadcaster::drain(std::size_t lane, const EncodedFrame& frame) {
    // deliver() only queues and starts asynchronous writes; it never closes a session
    // synchronously, so the index cannot change while it is walked.
    indexes_[lane].for_each(frame.subject_id, [&frame](ClientSession& session) { session.deliver(frame); });
}

void PoseBroadcaster::subscribe(std::size_t lane_index, const std::shared_ptr<ClientSession>& session,
                                const std::vector<std::uint32_t>& subjects, std::uint32_t fields,
                                std::optional<std::uint32_t> previous_fields) {
    SubscriptionIndex<ClientSession>& index = indexes_.at(lane_index);
    // The new selection is counted before the old one is released, so publish() never sees
    // a moment in which neither is in use and skips an encoding this client needs.
    field_users_[normalize_fields(fields)].fetch_add(1, std::memory_order_relaxed);
    if (previous_fields) field_users_[normalize_fields(*previous_fields)].fetch_sub(1, std::memory_order_relaxed);
    const int all_change = index.assign(
        session, subjects.empty(), subjects,
        [this](std::uint32_t s) { subject_interest_[s % kInterestSlots].fetch_add(1, std::memory_order_relaxed); },
        [this](std::uint32_t s) { subject_interest_[s % kInterestSlots].fetch_sub(1, std::memory_order_relaxed); });
    count_all_subject_users(all_change);
}

void PoseBroadcaster::unsubscribe(std::size_t lane_index, const ClientSession* session, std::uint32_t fields) {
    field_users_[normalize_fields(fields)].fetch_sub(1, std::memory_order_relaxed);
    const int all_change = indexes_.at(lane_index).remove(session, [this](std::uint32_t s) {
        subject_interest_[s % kInterestSlots].fetch_sub(1, std::memory_order_relaxed);
    });
    count_all_subject_users(all_change);
}

void PoseBroadcaster::count_all_subject_users(int change) {
    if (change > 0) all_subject_users_.fetch_add(1, std::memory_order_relaxed);
    if (change < 0) all_subject_users_.fetch_sub(1, std::memory_order_relaxed);
}

}  // namespace mocap::serve
