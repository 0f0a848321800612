// pose_broadcaster.cpp — encode once, hand over to each serve thread, fan out there.
#include "serve/pose_broadcaster.hpp"

#include <algorithm>
#include <chrono>

#include "serve/client_session.hpp"

namespace mocap::serve {

struct PoseBroadcaster::Lane {
    asio::io_context* io = nullptr;
    std::mutex mutex;                   // guards pending, wake_posted
    std::vector<EncodedFrame> pending;  // filled by publish()
    bool wake_posted = false;
    // Lane thread only:
    std::vector<EncodedFrame> draining;  // swapped with pending, so neither reallocates
    std::unordered_map<std::uint32_t, std::vector<std::shared_ptr<ClientSession>>> by_subject;
    std::vector<std::shared_ptr<ClientSession>> all_subjects;
};

PoseBroadcaster::PoseBroadcaster(const std::vector<asio::io_context*>& lanes, std::size_t backlog_frames,
                                 std::function<std::int64_t()> wall_clock_us, ServeCounters& counters)
    : backlog_frames_(std::max<std::size_t>(backlog_frames, 1)),
      wall_clock_us_(std::move(wall_clock_us)),
      counters_(counters) {
    if (!wall_clock_us_) {
        wall_clock_us_ = [] {
            return std::chrono::duration_cast<std::chrono::microseconds>(
                       std::chrono::system_clock::now().time_since_epoch())
                .count();
        };
    }
    for (asio::io_context* io : lanes) {
        auto lane = std::make_unique<Lane>();
        lane->io = io;
        lane->pending.reserve(backlog_frames_);
        lane->draining.reserve(backlog_frames_);
        lanes_.push_back(std::move(lane));
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

    for (auto& lane_ptr : lanes_) {
        Lane& lane = *lane_ptr;
        bool post = false;
        {
            std::lock_guard lock(lane.mutex);
            if (lane.pending.size() >= backlog_frames_) {
                // The lane's thread is not keeping up at all (not a slow client: those
                // drop in their own queues). Dropping here keeps publish() bounded.
                counters_.backlog_dropped.add();
                continue;
            }
            lane.pending.push_back(encoded);
            if (!lane.wake_posted) post = lane.wake_posted = true;
        }
        if (post) asio::post(*lane.io, [this, &lane] { drain(lane); });
    }
}

void PoseBroadcaster::drain(Lane& lane) {
    {
        std::lock_guard lock(lane.mutex);
        lane.draining.swap(lane.pending);
        lane.wake_posted = false;
    }
    // deliver() only queues and starts asynchronous writes; it never closes a session
    // synchronously, so the index cannot change while it is walked.
    for (const EncodedFrame& frame : lane.draining) {
        if (auto it = lane.by_subject.find(frame.subject_id); it != lane.by_subject.end()) {
            for (const auto& session : it->second)
                session->deliver(frame);
        }
        for (const auto& session : lane.all_subjects)
            session->deliver(frame);
    }
    lane.draining.clear();
}

void PoseBroadcaster::subscribe(std::size_t lane_index, const std::shared_ptr<ClientSession>& session,
                                const std::vector<std::uint32_t>& subjects, std::uint32_t fields) {
    Lane& lane = *lanes_.at(lane_index);
    field_users_[normalize_fields(fields)].fetch_add(1, std::memory_order_relaxed);
    if (subjects.empty()) {
        all_subject_users_.fetch_add(1, std::memory_order_relaxed);
        lane.all_subjects.push_back(session);
        return;
    }
    for (std::uint32_t subject : subjects) {
        subject_interest_[subject % kInterestSlots].fetch_add(1, std::memory_order_relaxed);
        lane.by_subject[subject].push_back(session);
    }
}

void PoseBroadcaster::unsubscribe(std::size_t lane_index, const ClientSession* session,
                                  const std::vector<std::uint32_t>& subjects, std::uint32_t fields) {
    Lane& lane = *lanes_.at(lane_index);
    field_users_[normalize_fields(fields)].fetch_sub(1, std::memory_order_relaxed);
    auto remove_from = [session](std::vector<std::shared_ptr<ClientSession>>& list) {
        std::erase_if(list, [session](const auto& s) { return s.get() == session; });
    };
    if (subjects.empty()) {
        all_subject_users_.fetch_sub(1, std::memory_order_relaxed);
        remove_from(lane.all_subjects);
        return;
    }
    for (std::uint32_t subject : subjects) {
        subject_interest_[subject % kInterestSlots].fetch_sub(1, std::memory_order_relaxed);
        auto it = lane.by_subject.find(subject);
        if (it == lane.by_subject.end()) continue;
        remove_from(it->second);
        if (it->second.empty()) lane.by_subject.erase(it);
    }
}

}  // namespace mocap::serve
