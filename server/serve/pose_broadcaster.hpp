// pose_broadcaster.hpp — fan-out of encoded frames to the client sessions.
//
// publish() is called by the daemon's assembler thread(s). It encodes the frame once
// per field selection that some client uses (nothing when nobody watches the subject),
// then hands
// the shared buffers to every serve thread ("lane") through a small mutex-guarded
// backlog and one wake-up post (publish_backlog.hpp, shared with live BVH and HTTP). On its own thread, each lane walks
// its subscription index (subscription_index.hpp) and gives the frame to each subscribed session, which queues it
// (bounded, drop-oldest) and writes it when its previous write has completed. publish() never waits for a client: its
// cost is the encoding plus one short lock per lane. A (re)subscription costs what that client changes, never what
// others subscribed.
//
// Thread-safety: publish() and the field-user counts from any thread; subscribe(),
// unsubscribe() and drain only on the owning lane's io_context thread.
// Memory: backlog vectors are reserved at construction (publish_backlog_frames per
// lane); each published frame allocates only its encoded buffers.
#pragma once

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <vector>

#include "core/asio.hpp"
#include "core/frame.hpp"
#include "serve/pose_encoder.hpp"
#include "serve/publish_backlog.hpp"
#include "serve/serve_counters.hpp"
#include "serve/subscription_index.hpp"
#include "skeleton/skeleton_pose.hpp"

namespace mocap::serve {

class ClientSession;

/// One frame as every client may receive it: one shared buffer per field selection in
/// use (index = normalised fields; null where nobody subscribed with that selection).
struct EncodedFrame {
    std::uint32_t subject_id = 0;
    std::uint64_t sync = 0;
    std::array<SharedBytes, kFieldCombinations> by_fields{};
};

class PoseBroadcaster {
public:
    /// `lanes`: one io_context per serve thread (not owned; must outlive this object).
    PoseBroadcaster(const std::vector<asio::io_context*>& lanes, std::size_t backlog_frames,
                    std::function<std::int64_t()> wall_clock_us, ServeCounters& counters);
    ~PoseBroadcaster();
    PoseBroadcaster(const PoseBroadcaster&) = delete;
    PoseBroadcaster& operator=(const PoseBroadcaster&) = delete;

    /// Any thread. Encodes and queues `frame` for every lane; returns at once.
    /// Precondition: as PoseEncoder::encode_frame.
    void publish(const SubjectFrame& frame, const skeleton::SkeletonPose& pose);

    /// After stop(), publish() is a no-op (used while the server shuts down).
    void stop() { stopped_.store(true, std::memory_order_release); }

    /// Lane thread only. Makes `session`'s subscription `subjects` (sorted, unique; empty =
    /// every subject) with `fields` (normalised), replacing the one it had with
    /// `previous_fields` (nullopt = not subscribed). Costs O(old + new subjects) comparisons
    /// and O(1) per subject that changes.
    void subscribe(std::size_t lane, const std::shared_ptr<ClientSession>& session,
                   const std::vector<std::uint32_t>& subjects, std::uint32_t fields,
                   std::optional<std::uint32_t> previous_fields);
    /// Lane thread only; removes `session` (subscribed with `fields`) from the index.
    void unsubscribe(std::size_t lane, const ClientSession* session, std::uint32_t fields);

    [[nodiscard]] std::size_t lane_count() const { return indexes_.size(); }

private:
    void drain(std::size_t lane, const EncodedFrame& frame);
    void count_all_subject_users(int change);

    std::vector<SubscriptionIndex<ClientSession>> indexes_;  // one per lane, used on its thread
    LaneBacklog<EncodedFrame> backlog_;
    std::function<std::int64_t()> wall_clock_us_;
    ServeCounters& counters_;
    std::atomic<bool> stopped_{false};
    std::array<std::atomic<std::uint32_t>, kFieldCombinations> field_users_{};
    /// Subscriptions per subject slot (subject_id % kInterestSlots) and for all subjects:
    /// publish() skips encoding frames of subjects nobody watches. Slots are shared by
    /// subject ids that collide, which only costs an unneeded encoding.
    static constexpr std::size_t kInterestSlots = 1024;
    std::array<std::atomic<std::uint32_t>, kInterestSlots> subject_interest_{};
    std::atomic<std::uint32_t> all_subject_users_{0};

    std::mutex encode_mutex_;  ///< guards encoder_ (publishers may be several threads)
    PoseEncoder encoder_;
};

}  // namespace mocap::serve
