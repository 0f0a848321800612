// take_recorder.cpp — a take's life: directory and sidecar, the raw recorder, the final sidecar.
#include "serve/take_recorder.hpp"

#include <spdlog/spdlog.h>
#include <sys/statvfs.h>

#include <algorithm>
#include <ctime>
#include <filesystem>

namespace mocap::serve {

namespace fs = std::filesystem;

TakeRecorder::TakeRecorder(TakeStore& store, TakeRecorderConfig config, const Clock& clock)
    : store_(store), config_(std::move(config)), clock_(clock) {
    group_.add("takes_started", started_);
    group_.add("takes_stopped", stopped_);
    group_.add("takes_refused", refused_);
    group_.add("takes_refused_disk_full", refused_disk_full_);
    group_.add("samples_recorded", recorded_);
    group_.add("samples_lost", lost_);
}

TakeRecorder::~TakeRecorder() {
    if (active_.load()) (void)stop();
}

std::string TakeRecorder::default_name(std::int64_t now_us) const {
    const auto t = static_cast<std::time_t>(now_us / 1'000'000);
    std::tm tm{};
    gmtime_r(&t, &tm);
    char buf[32];
    std::strftime(buf, sizeof buf, "take-%Y%m%d-%H%M%S", &tm);
    std::string name = buf;
    for (int n = 2; store_.find(name) && n < 1000; ++n)
        name = std::string(buf) + "-" + std::to_string(n);
    return name;
}

std::string TakeRecorder::short_of_space() const {
    if (config_.min_free_bytes == 0) return {};
    // The store's root is created on first use: before that its parent's file system holds it.
    fs::path at = store_.root();
    std::error_code ec;
    while (!at.empty() && !fs::exists(at, ec) && at.has_parent_path() && at.parent_path() != at)
        at = at.parent_path();
    struct statvfs st {};
    if (::statvfs(at.c_str(), &st) != 0) return {};  // the create below says what is wrong
    const std::uint64_t avail = static_cast<std::uint64_t>(st.f_bavail) * st.f_frsize;
    if (avail >= config_.min_free_bytes) return {};
    const auto mib = [](std::uint64_t b) {
        return std::to_string(b >> 20) + "." + std::to_string(((b & 0xFFFFF) * 10) >> 20);
    };
    return "not enough free space for a take: " + mib(avail) + " MiB free on " + at.string() + ", " +
           mib(config_.min_free_bytes) +
           " MiB kept in reserve ([outputs] take_start_min_free_mb); free some space (delete takes or raw files) "
           "and start again";
}

std::vector<std::string> TakeRecorder::copy_calibrations(const std::string& dir) const {
    std::vector<std::string> copied;
    if (config_.calibration_dir.empty()) return copied;
    std::error_code ec;
    for (const auto& f : fs::directory_iterator(config_.calibration_dir, ec)) {
        const std::string file = f.path().filename().string();
        if (!file.starts_with("calibration-subject-") || f.path().extension() != ".toml") continue;
        if (fs::copy_file(f.path(), fs::path(dir) / file, ec)) {
            copied.push_back(file);
        } else {
            spdlog::warn("take: cannot copy {} into {}: {}", f.path().string(), dir, ec.message());
        }
    }
    std::sort(copied.begin(), copied.end());
    return copied;
}

ControlResult TakeRecorder::start(const std::string& name, const std::string& notes) {
    std::lock_guard control(control_mutex_);
    auto refuse = [this](std::string why) {
        refused_.add();
        return ControlResult::failure(std::move(why));
    };
    if (active_.load()) return refuse("take '" + meta_.name + "' is running; stop it first");
    if (notes.size() > kMaxTakeNotesBytes) return refuse("notes longer than 4096 bytes");
    if (std::string why = short_of_space(); !why.empty()) {
        refused_disk_full_.add();
        spdlog::warn("take start refused: {}", why);
        return refuse(std::move(why));
    }
    const std::int64_t now = clock_.now_us();
    TakeMeta meta;
    meta.name = name.empty() ? default_name(now) : name;
    meta.start_us = now;
    meta.filter = config_.filter;
    meta.notes = notes;
    std::string error;
    // Marked first: from its creation on, a delete of this take is refused.
    store_.mark_recording(meta.name);
    if (!store_.create(meta, &error)) {
        store_.mark_recording("");
        return refuse(error);
    }
    const std::string dir = store_.dir(meta.name);
    meta.calibration = copy_calibrations(dir);
    RawRecorderConfig raw = config_.raw;
    raw.directory = dir;
    raw.rotate_bytes = 0;  // one file per take
    raw.rotate_s = 0;
    auto recorder = std::make_unique<RawRecorder>(raw, clock_);
    if (!store_.save(meta, &error) || !recorder->start(&error)) {
        store_.mark_recording("");
        std::string ignored;
        (void)store_.remove(meta.name, &ignored);
        return refuse(error);
    }
    {
        std::lock_guard hand_over(push_mutex_);
        recorder_ = std::move(recorder);
        subject_count_ = 0;
    }
    active_.store(true, std::memory_order_release);
    meta_ = meta;
    started_.add();
    spdlog::info("take '{}' started in {}", meta.name, dir);
    ControlResult ok = ControlResult::success();
    ok.take = meta.name;
    return ok;
}

ControlResult TakeRecorder::stop() {
    std::lock_guard control(control_mutex_);
    if (!active_.load()) {
        refused_.add();
        return ControlResult::failure("no take is running");
    }
    std::unique_ptr<RawRecorder> recorder;
    {
        std::lock_guard hand_over(push_mutex_);
        active_.store(false, std::memory_order_relaxed);
        recorder = std::move(recorder_);
        meta_.subjects.assign(subjects_.begin(), subjects_.begin() + static_cast<std::ptrdiff_t>(subject_count_));
    }
    // No push() reaches this recorder any more: its producer has stopped, as stop() requires.
    recorder->stop();
    const auto value = [&recorder](const char* n) { return recorder->counters().value(n).value_or(0); };
    meta_.stop_us = clock_.now_us();
    std::sort(meta_.subjects.begin(), meta_.subjects.end());
    meta_.samples = value("samples_recorded");
    meta_.samples_lost = value("samples_dropped") + value("samples_lost");
    meta_.loss.clear();
    if (value("samples_lost") > 0) {
        meta_.loss = recorder->first_failure().empty() ? "the disk refused them" : recorder->first_failure();
    }
    if (value("samples_dropped") > 0) {
        meta_.loss += std::string(meta_.loss.empty() ? "" : "; ") + std::to_string(value("samples_dropped")) +
                      " dropped: the recorder's ring was full";
    }
    recorded_.add(meta_.samples);
    lost_.add(meta_.samples_lost);
    stopped_.add();
    store_.mark_recording("");
    ControlResult result = ControlResult::success();
    std::string error;
    if (!store_.save(meta_, &error)) {
        // The raw file is complete; the start sidecar stays and the take lists as not stopped.
        spdlog::error("take '{}': {}", meta_.name, error);
        result = ControlResult::failure("take stopped, but its metadata was not updated: " + error);
    }
    if (meta_.samples_lost > 0) {
        // Not a bare ok: whoever stops the take learns at once that it is incomplete.
        spdlog::warn("take '{}' stopped: {} samples, {} lost ({})", meta_.name, meta_.samples, meta_.samples_lost,
                     meta_.loss);
        result = ControlResult::failure("take '" + meta_.name + "' stopped with " + std::to_string(meta_.samples_lost) +
                                        " samples lost (" + meta_.loss + "); the take holds " +
                                        std::to_string(meta_.samples) + " samples" +
                                        (result.ok ? std::string() : "; " + result.error));
    } else {
        spdlog::info("take '{}' stopped: {} samples, {} lost", meta_.name, meta_.samples, meta_.samples_lost);
    }
    result.take = meta_.name;
    return result;
}

void TakeRecorder::push(const SegmentSample& sample) noexcept {
    if (!active_.load(std::memory_order_acquire)) return;
    std::lock_guard hand_over(push_mutex_);
    if (!recorder_) return;
    recorder_->push(sample);
    const auto seen = subjects_.begin() + static_cast<std::ptrdiff_t>(subject_count_);
    if (subject_count_ < subjects_.size() && std::find(subjects_.begin(), seen, sample.subject_id) == seen) {
        subjects_[subject_count_++] = sample.subject_id;
    }
}

}  // namespace mocap::serve
