// subject_assembler.cpp — per-subject frame assembly. The rules are in the header; the
// notes here say why the code takes the shape it does.
#include "core/subject_assembler.hpp"

#include <algorithm>
#include <stdexcept>

namespace mocap {
namespace {

constexpr std::uint32_t bit(std::size_t k) noexcept {
    return std::uint32_t{1} << k;
}

// Earliest non-zero stamp: a frame's ingest-side stamps describe its first segment, so
// sink-send -> client latency is measured for the segment that waited longest.
void keep_earliest(std::int64_t& acc, std::int64_t v) noexcept {
    if (v != 0 && (acc == 0 || v < acc)) acc = v;
}

}  // namespace

void AssemblerCounters::add_to(CounterGroup& group) const {
    group.add("frames_complete", frames_complete);
    group.add("frames_partial", frames_partial);
    group.add("frames_forced", frames_forced);
    group.add("segments_late", segments_late);
    group.add("segments_stale", segments_stale);
    group.add("segments_duplicate", segments_duplicate);
    group.add("segments_invalid", segments_invalid);
}

SubjectAssembler::SubjectAssembler(std::uint32_t subject_id, std::uint16_t segment_count, const AssemblerConfig& config,
                                   FrameSink& sink, LatencyHistogram* assembly)
    : subject_id_(subject_id),
      segment_count_(segment_count),
      all_mask_(segment_count >= 32 ? ~std::uint32_t{0} : bit(segment_count) - 1),
      config_(config),
      sink_(sink),
      assembly_(assembly) {
    static_assert(kMaxSegments <= 32, "segment masks are 32-bit");
    if (segment_count == 0 || segment_count > kMaxSegments) {
        throw std::invalid_argument("SubjectAssembler: segment_count must be 1..kMaxSegments");
    }
    if (config_.window == 0) throw std::invalid_argument("SubjectAssembler: window must be >= 1");
    instants_.resize(config_.window);
}

std::size_t SubjectAssembler::oldest_index() const noexcept {
    if (open_count_ == 0) return kNoSlot;
    // Cached: the window is scanned once per emitted frame, not once per pose.
    if (oldest_index_ == kNoSlot) {
        for (std::size_t i = 0; i < instants_.size(); ++i) {
            const Instant& in = instants_[i];
            if (in.open && (oldest_index_ == kNoSlot || in.frame.sync < instants_[oldest_index_].frame.sync)) {
                oldest_index_ = i;
            }
        }
    }
    return oldest_index_;
}

SubjectAssembler::Instant* SubjectAssembler::oldest() noexcept {
    const std::size_t i = oldest_index();
    return i == kNoSlot ? nullptr : &instants_[i];
}

bool SubjectAssembler::resolved(const Instant& in) const noexcept {
    std::uint32_t missing = all_mask_ & ~in.have_mask;
    if (config_.skip_dead_segments) missing &= ~dead_mask_;
    for (std::size_t k = 0; missing != 0; ++k, missing >>= 1) {
        if ((missing & 1u) == 0) continue;
        // Segments arrive in order: a newer pose means this instant's will never come.
        const bool moved_on = (seen_mask_ & bit(k)) != 0 && newest_sync_[k] > in.frame.sync;
        if (!moved_on) return false;
    }
    return true;
}

void SubjectAssembler::emit(Instant& in, std::int64_t now_us) {
    out_.subject_id = subject_id_;
    out_.sync = in.frame.sync;
    out_.sample_us = in.frame.sample_us;
    out_.times = in.frame.times;
    out_.times.assembled_us = now_us;
    out_.segment_count = segment_count_;
    std::uint64_t stale = 0;
    for (std::size_t k = 0; k < segment_count_; ++k) {
        if ((in.have_mask & bit(k)) != 0) {
            out_.segments[k] = in.frame.segments[k];
            continue;
        }
        ++stale;
        if ((seen_mask_ & bit(k)) != 0) {
            out_.segments[k] = last_good_[k];
            out_.segments[k].flags =
                static_cast<std::uint8_t>((out_.segments[k].flags & ~kSegmentNeverSeen) | kSegmentStale);
            // Missing without having moved on: stop waiting for it until it speaks again.
            if (newest_sync_[k] < in.frame.sync) dead_mask_ |= bit(k);
        } else {
            out_.segments[k] = SegmentPose{};
            out_.segments[k].flags = kSegmentStale | kSegmentNeverSeen;
            dead_mask_ |= bit(k);
        }
    }
    if (stale == 0) {
        stats_.frames_complete.add();
    } else {
        stats_.frames_partial.add();
        stats_.segments_stale.add(stale);
    }
    if (assembly_ != nullptr && out_.times.filtered_us != 0) {
        assembly_->record(now_us - out_.times.filtered_us);
    }
    emitted_any_ = true;
    last_emitted_sync_ = in.frame.sync;
    in.open = false;
    --open_count_;
    oldest_index_ = kNoSlot;
    sink_.on_frame(out_);
}

void SubjectAssembler::emit_due(std::int64_t now_us, bool all) {
    while (Instant* in = oldest()) {
        const bool due = all || resolved(*in) || now_us - in->first_us >= config_.deadline_us;
        if (!due) break;
        emit(*in, now_us);
    }
}

void SubjectAssembler::on_pose(const PoseUpdate& u, std::int64_t now_us) {
    if (u.subject_id != subject_id_ || u.segment_index >= segment_count_) {
        stats_.segments_invalid.add();
        return;
    }
    const std::size_t k = u.segment_index;
    // The hold follows the newest pose whatever happens to this one below.
    if ((seen_mask_ & bit(k)) == 0 || u.sync > newest_sync_[k]) {
        last_good_[k] = u.pose;
        newest_sync_[k] = u.sync;
    }
    seen_mask_ |= bit(k);
    dead_mask_ &= ~bit(k);

    if (emitted_any_ && u.sync <= last_emitted_sync_) {
        stats_.segments_late.add();
        emit_due(now_us, false);  // this segment moving on may resolve the oldest instant
        return;
    }
    // Keep open instants within one window: force out those a window or more behind.
    const std::uint64_t window = config_.window;
    while (Instant* old = oldest()) {
        if (u.sync < window || old->frame.sync > u.sync - window) break;
        stats_.frames_forced.add();
        emit(*old, now_us);
    }
    Instant& in = instants_[u.sync % window];
    if (in.open && in.frame.sync != u.sync) {
        // The slot holds a newer instant: this pose is a window or more behind it.
        stats_.segments_late.add();
        return;
    }
    if (!in.open) {
        in.open = true;
        in.first_us = now_us;
        in.have_mask = 0;
        in.frame.sync = u.sync;
        in.frame.sample_us = u.pose.sample_us;
        in.frame.times = u.times;
        const std::size_t slot = u.sync % window;
        if (open_count_ == 0 || (oldest_index_ != kNoSlot && u.sync < instants_[oldest_index_].frame.sync)) {
            oldest_index_ = slot;
        }
        ++open_count_;
    } else if ((in.have_mask & bit(k)) != 0) {
        stats_.segments_duplicate.add();
        return;
    } else {
        StageTimes& t = in.frame.times;
        keep_earliest(t.sink_send_us, u.times.sink_send_us);
        keep_earliest(t.received_us, u.times.received_us);
        t.dequeued_us = std::max(t.dequeued_us, u.times.dequeued_us);
        t.filtered_us = std::max(t.filtered_us, u.times.filtered_us);
    }
    in.frame.segments[k] = u.pose;
    in.have_mask |= bit(k);
    emit_due(now_us, false);
}

void SubjectAssembler::advance(std::int64_t now_us) {
    emit_due(now_us, false);
}

void SubjectAssembler::flush(std::int64_t now_us) {
    emit_due(now_us, true);
}

std::int64_t SubjectAssembler::next_deadline_us() const noexcept {
    const std::size_t i = oldest_index();
    return i == kNoSlot ? kNoDeadline : instants_[i].first_us + config_.deadline_us;
}

AssemblerSet::AssemblerSet(const AssemblerConfig& config, FrameSink& sink) : config_(config), sink_(sink) {
    counters_.add("poses_unknown_subject", unknown_subject_);
}

SubjectAssembler& AssemblerSet::add_subject(std::uint32_t subject_id, std::uint16_t segment_count) {
    auto pos = std::lower_bound(
        subjects_.begin(), subjects_.end(), subject_id,
        [](const std::unique_ptr<SubjectAssembler>& s, std::uint32_t id) { return s->subject_id() < id; });
    if (pos != subjects_.end() && (*pos)->subject_id() == subject_id) {
        throw std::logic_error("AssemblerSet::add_subject: subject added twice");
    }
    auto subject = std::make_unique<SubjectAssembler>(subject_id, segment_count, config_, sink_, &assembly_);
    subject->stats().add_to(counters_);
    return **subjects_.insert(pos, std::move(subject));
}

SubjectAssembler* AssemblerSet::lookup(std::uint32_t subject_id) const noexcept {
    auto pos = std::lower_bound(
        subjects_.begin(), subjects_.end(), subject_id,
        [](const std::unique_ptr<SubjectAssembler>& s, std::uint32_t id) { return s->subject_id() < id; });
    return (pos != subjects_.end() && (*pos)->subject_id() == subject_id) ? pos->get() : nullptr;
}

void AssemblerSet::on_pose(const PoseUpdate& update, std::int64_t now_us) {
    SubjectAssembler* subject = lookup(update.subject_id);
    if (subject == nullptr) {
        unknown_subject_.add();
        return;
    }
    subject->on_pose(update, now_us);
}

void AssemblerSet::advance(std::int64_t now_us) {
    for (auto& s : subjects_)
        s->advance(now_us);
}

void AssemblerSet::flush(std::int64_t now_us) {
    for (auto& s : subjects_)
        s->flush(now_us);
}

std::int64_t AssemblerSet::next_deadline_us() const noexcept {
    std::int64_t next = kNoDeadline;
    for (const auto& s : subjects_)
        next = std::min(next, s->next_deadline_us());
    return next;
}

void AssemblerSet::set_deadline_us(std::int64_t deadline_us) noexcept {
    config_.deadline_us = deadline_us;
    for (auto& s : subjects_)
        s->set_deadline_us(deadline_us);
}

void AssemblerSet::register_metrics(MetricsRegistry& registry) const {
    registry.add(counters_);
    registry.add_latency("assembly", [this] { return assembly_snapshot(); });
    // subjects_ is fixed after set-up, so the count is read without the assembler thread.
    registry.add_gauge("subjects_configured", "Subjects the pipeline was built for",
                       [this] { return static_cast<double>(subject_count()); });
}

const SubjectAssembler* AssemblerSet::find(std::uint32_t subject_id) const noexcept {
    return lookup(subject_id);
}

}  // namespace mocap
