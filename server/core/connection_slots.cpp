// connection_slots.cpp — the admission rules of connection_slots.hpp.
#include "core/connection_slots.hpp"

namespace mocap {

ConnectionSlots::Admission ConnectionSlots::admit(const std::string& address, bool loopback, std::int64_t now_us) {
    std::lock_guard lock(mutex_);
    Admission out;
    const PeerLimits& peers = policy_.peers;
    const bool limited = peers.max_per_address > 0 && (!loopback || peers.limit_loopback);
    if (limited) {
        const auto it = per_address_.find(address);
        if (it != per_address_.end() && it->second >= peers.max_per_address) {
            out.verdict = Verdict::kRefusedPerAddress;
            return out;
        }
    }
    out.verdict = Verdict::kAdmitted;
    if (slots_.size() >= policy_.max_connections) {
        const std::shared_ptr<Slot> victim = victim_locked(now_us);
        if (!victim) {
            out.verdict = Verdict::kRefusedFull;
            return out;
        }
        out.verdict = Verdict::kAdmittedEvicting;
        out.evicted = victim->id_;
        erase_locked(slots_.find(victim->id_));
    }
    out.slot = std::make_shared<Slot>(next_id_++, address, limited, now_us);
    slots_.emplace(out.slot->id_, out.slot);
    if (limited) ++per_address_[address];
    return out;
}

std::shared_ptr<ConnectionSlots::Slot> ConnectionSlots::victim_locked(std::int64_t now_us) const {
    std::shared_ptr<Slot> unproven, stalled;
    // Progress at or before this is a stall.
    std::int64_t stalled_since = now_us - static_cast<std::int64_t>(policy_.peers.stall_evict_s * 1e6);
    for (const auto& [id, slot] : slots_) {
        const std::int64_t last = slot->last_progress_us_.load(std::memory_order_relaxed);
        if (last == 0) {
            if (!unproven || slot->opened_us_ < unproven->opened_us_ ||
                (slot->opened_us_ == unproven->opened_us_ && slot->id_ < unproven->id_)) {
                unproven = slot;
            }
        } else if (last <= stalled_since) {
            stalled_since = last;
            stalled = slot;
        }
    }
    return unproven ? unproven : stalled;
}

void ConnectionSlots::release(std::uint64_t id) {
    std::lock_guard lock(mutex_);
    const auto it = slots_.find(id);
    if (it != slots_.end()) erase_locked(it);
}

void ConnectionSlots::erase_locked(std::unordered_map<std::uint64_t, std::shared_ptr<Slot>>::iterator it) {
    const Slot& slot = *it->second;
    if (slot.limited_) {
        const auto a = per_address_.find(slot.address_);
        if (a != per_address_.end() && --a->second == 0) per_address_.erase(a);
    }
    slots_.erase(it);
}

std::size_t ConnectionSlots::size() const {
    std::lock_guard lock(mutex_);
    return slots_.size();
}

}  // namespace mocap
