// connection_slots.hpp — the connection slots of one listening port: who may take one, and
// which open connection gives its slot up when the port is full (docs/security.md,
// "Connection slots"). Shared by every listener: sinks (ingest), poses, live BVH and HTTP.
//
// Why: a slot used to be held by whoever connected first. A peer that sends nothing useful
// (one byte every two seconds), or never reads, held its slot forever, and enough of them
// locked real sinks and viewers out. An attacker and a real sink may share an address (NAT,
// loopback), so a per-address limit alone cannot tell them apart; what a real peer does
// and an idle one does not is *progress*: whole valid packets, requests or messages, and
// writes it drains. The owner of a connection reports that with Slot::progress().
//
// Rules for a new connection, in order (admit()):
//  1. Its address already holds `max_per_address` slots (0 = no such limit; loopback peers
//     are exempt unless `limit_loopback`: tests, the soak, the load tool and a local TLS
//     proxy all connect from 127.0.0.1): refused (kRefusedPerAddress).
//  2. A slot is free: admitted.
//  3. The port is full: the slot of a connection that has not proven itself (no progress
//     yet; the oldest such first) is taken; failing that, the slot of the proven connection
//     whose last progress is oldest, if that is at least `stall_evict_s` ago
//     (kAdmittedEvicting; the caller closes the victim, whose slot is already gone).
//  4. Otherwise refused (kRefusedFull).
//
// Thread-safety: admit(), release() and size() take an internal mutex (any thread; the
// lanes of the pose service share one table). Slot::progress() is one relaxed atomic store
// on the connection's own thread, so it may sit on the per-packet path.
// Cost: admit() is O(1) while slots are free and O(open connections) when the port is full.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <unordered_map>

namespace mocap {

/// The `[limits]` settings of one port (config/mocapd.toml).
struct PeerLimits {
    std::size_t max_per_address = 0;  ///< slots one peer address may hold; 0 = no limit
    bool limit_loopback = false;      ///< apply max_per_address to loopback peers too
    double stall_evict_s = 5.0;       ///< a proven connection without progress this long may be evicted
};

struct SlotPolicy {
    std::size_t max_connections = 64;  ///< slots of the port
    PeerLimits peers{};
};

class ConnectionSlots {
public:
    /// One connection's slot. The connection keeps it (shared) and reports progress on it.
    class Slot {
    public:
        Slot(std::uint64_t id, std::string address, bool limited, std::int64_t opened_us)
            : id_(id), address_(std::move(address)), limited_(limited), opened_us_(opened_us) {}
        /// A whole valid packet, request or message arrived, or the peer drained a write.
        void progress(std::int64_t now_us) noexcept {
            last_progress_us_.store(now_us > 0 ? now_us : 1, std::memory_order_relaxed);
        }
        [[nodiscard]] bool proven() const noexcept { return last_progress_us_.load(std::memory_order_relaxed) != 0; }
        [[nodiscard]] std::uint64_t id() const noexcept { return id_; }
        [[nodiscard]] const std::string& address() const noexcept { return address_; }

    private:
        friend class ConnectionSlots;
        std::uint64_t id_;
        std::string address_;
        bool limited_;  // counts against max_per_address
        std::int64_t opened_us_;
        std::atomic<std::int64_t> last_progress_us_{0};  // 0 = never
    };

    enum class Verdict { kAdmitted, kAdmittedEvicting, kRefusedPerAddress, kRefusedFull };
    struct Admission {
        Verdict verdict = Verdict::kRefusedFull;
        std::shared_ptr<Slot> slot;  ///< set when admitted; slot->id() is never 0 nor reused
        std::uint64_t evicted = 0;   ///< kAdmittedEvicting: the id of the connection to close
        [[nodiscard]] bool admitted() const { return slot != nullptr; }
    };

    explicit ConnectionSlots(const SlotPolicy& policy) : policy_(policy) {}

    /// Decides for a new connection from `address` (rules above) and, if admitted, takes
    /// its slot (and frees the victim's).
    Admission admit(const std::string& address, bool loopback, std::int64_t now_us);
    /// The connection `id` closed: frees its slot. Unknown ids (an evicted one) are ignored.
    void release(std::uint64_t id);

    [[nodiscard]] std::size_t size() const;
    [[nodiscard]] const SlotPolicy& policy() const { return policy_; }

private:
    void erase_locked(std::unordered_map<std::uint64_t, std::shared_ptr<Slot>>::iterator it);
    std::shared_ptr<Slot> victim_locked(std::int64_t now_us) const;

    const SlotPolicy policy_;
    mutable std::mutex mutex_;
    std::unordered_map<std::uint64_t, std::shared_ptr<Slot>> slots_;  // guarded
    std::unordered_map<std::string, std::size_t> per_address_;        // guarded; limited slots only
    std::uint64_t next_id_ = 1;                                       // guarded
};

}  // namespace mocap
