#include "serve/bvh_recorder.hpp"

#include <fcntl.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <optional>
#include <sstream>

#include "core/errno_text.hpp"
#include "skeleton/bvh.hpp"

namespace mocap::serve {

namespace {

std::string count_digits(std::uint64_t frames) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%0*llu", kBvhCountDigits, static_cast<unsigned long long>(frames));
    return buf;
}

// A measured Frame Time is rewritten in place, so it keeps the width of this placeholder:
// "%.6f" of a value in [0.000001, 9.999999] is eight characters.
constexpr double kUnmeasuredFrameTimeS = 0.01;
double fit(double seconds) {
    return std::clamp(seconds, 0.000001, 9.999999);
}

}  // namespace

BvhRecorder::BvhRecorder(BvhRecorderConfig config, const BvhFrameEncoder& encoder, FileWriter& writer)
    : config_(std::move(config)), encoder_(encoder), file_writer_(writer) {
    group_.add("recordings_started", started_);
    group_.add("frames_recorded", recorded_);
    group_.add("frames_dropped", dropped_);
    group_.add("frames_lost", lost_);
    group_.add("write_errors", write_errors_);
    group_.add("disk_full", disk_full_);
    group_.add("recordings_failed", failed_);
    line_.reserve(16 * encoder_.values_per_frame());
}

BvhRecorder::~BvhRecorder() {
    std::lock_guard control(control_mutex_);
    finish();
}

bool BvhRecorder::start(const std::string& requested, std::string* error, std::string* opened_path) {
    std::lock_guard control(control_mutex_);
    if (recording()) {
        *error = "a BVH recording is already running";
        return false;
    }
    finish();  // a recording that stopped on a write failure (logged then)
    std::string path = requested;
    int fd = -1;
    if (path.empty()) {
        // First free mocap-<n>.bvh: O_EXCL makes the choice race-free.
        for (int n = 1; n < 100000 && fd < 0; ++n) {
            path = config_.directory + "/mocap-" + std::to_string(n) + ".bvh";
            fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
            if (fd < 0 && errno != EEXIST) break;
        }
    } else {
        fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
    }
    if (fd < 0) {
        *error = "cannot create " + path + ": " + errno_text(errno);
        return false;
    }
    return start_locked(fd, path, true, error, opened_path);
}

bool BvhRecorder::start_fd(int fd, const std::string& name, std::string* error) {
    std::lock_guard control(control_mutex_);
    if (recording()) {
        *error = "a BVH recording is already running";
        return false;
    }
    finish();
    const int own = ::fcntl(fd, F_DUPFD_CLOEXEC, 0);
    if (own < 0) {
        *error = "cannot write " + name + ": " + errno_text(errno);
        return false;
    }
    return start_locked(own, name, false, error, nullptr);
}

bool BvhRecorder::start_locked(int fd, const std::string& path, bool created, std::string* error,
                               std::string* opened_path) {
    const std::string head = encoder_.hierarchy() + "MOTION\nFrames: ";
    const std::string header = head + count_digits(0) + "\n" + encoder_.frame_time_line(kUnmeasuredFrameTimeS);
    if (const int err = write_whole(file_writer_, fd, header.data(), header.size(), 0); err != 0) {
        if (is_disk_full(err)) disk_full_.add();
        write_errors_.add();
        *error = "cannot write " + path + ": " + errno_text(err);
        ::close(fd);
        if (created) ::unlink(path.c_str());  // a file without its header is no recording
        return false;
    }
    fd_ = fd;
    path_ = path;
    count_offset_ = head.size();
    file_end_ = header.size();
    frames_written_ = 0;
    failure_.clear();
    {
        std::lock_guard lock(mutex_);
        pending_.clear();
        pending_frames_ = 0;
        stop_writer_ = false;
        subject_ = config_.subject;
        interval_ = FrameInterval();
    }
    writer_ = std::thread([this] {
        pthread_setname_np(pthread_self(), "mocap-bvhrec");
        writer_loop();
    });
    started_.add();
    recording_.store(true, std::memory_order_release);
    spdlog::info("bvh record: writing {}", path);
    if (opened_path) *opened_path = path;
    return true;
}

bool BvhRecorder::stop(std::string* error, std::uint64_t* frames) {
    std::lock_guard control(control_mutex_);
    if (!writer_.joinable()) {
        *error = "no BVH recording is running";
        return false;
    }
    finish();
    if (frames) *frames = frames_written_;
    if (!failure_.empty()) {
        *error = failure_;
        return false;
    }
    return true;
}

void BvhRecorder::finish() {
    if (!writer_.joinable()) return;
    recording_.store(false, std::memory_order_release);
    {
        std::lock_guard lock(mutex_);
        stop_writer_ = true;
    }
    wake_.notify_one();
    writer_.join();
    {
        // Frames that arrived after a failed write stopped the writer.
        std::lock_guard lock(mutex_);
        lost_.add(pending_frames_);
        pending_.clear();
        pending_frames_ = 0;
    }
    ::close(fd_);
    fd_ = -1;
    spdlog::info("bvh record: closed {} after {} frames", path_, frames_written_);
}

void BvhRecorder::publish(const SubjectFrame& frame, const skeleton::SkeletonPose& pose) {
    if (!recording_.load(std::memory_order_acquire)) return;
    std::lock_guard lock(mutex_);
    if (subject_ == 0) subject_ = frame.subject_id;
    if (frame.subject_id != subject_) return;
    interval_.add(frame.sync, frame.sample_us);
    line_.clear();
    encoder_.append_motion_line(pose, line_);
    if (pending_.size() + line_.size() > config_.max_buffer_bytes) {
        dropped_.add();
        return;
    }
    pending_ += line_;
    ++pending_frames_;
}

bool BvhRecorder::write_pending(std::string& scratch) {
    std::uint64_t frames = 0;
    std::optional<double> frame_time_s;
    {
        std::lock_guard lock(mutex_);
        scratch.swap(pending_);
        frames = pending_frames_;
        pending_frames_ = 0;
        frame_time_s = interval_.seconds();
    }
    if (scratch.empty()) return true;
    // Lines first, then the count; a failure of either cuts the file back to its last
    // whole line, so the count written before still matches the lines.
    int err = write_whole(file_writer_, fd_, scratch.data(), scratch.size(), static_cast<off_t>(file_end_));
    if (err == 0) {
        // The count and, when measured, the Frame Time right after it: one write.
        std::string digits = count_digits(frames_written_ + frames);
        if (!encoder_.fixed_frame_time() && frame_time_s) digits += "\n" + encoder_.frame_time_line(fit(*frame_time_s));
        if (digits.back() == '\n') digits.pop_back();
        err = write_whole(file_writer_, fd_, digits.data(), digits.size(), static_cast<off_t>(count_offset_));
        if (err != 0) {
            while (file_writer_.ftruncate(fd_, static_cast<off_t>(file_end_)) != 0 && errno == EINTR) {
            }
        }
    }
    const std::size_t bytes = scratch.size();
    scratch.clear();
    if (err != 0) {
        write_errors_.add();
        if (is_disk_full(err)) disk_full_.add();
        failed_.add();
        lost_.add(frames);
        failure_ = "BVH recording stopped early: write to " + path_ + " failed: " + errno_text(err) +
                   "; the file holds " + std::to_string(frames_written_) + " whole frames";
        spdlog::error("bvh record: {}", failure_);
        return false;
    }
    file_end_ += bytes;
    frames_written_ += frames;
    recorded_.add(frames);
    return true;
}

void BvhRecorder::writer_loop() {
    std::string scratch;
    const auto interval = std::chrono::microseconds(static_cast<std::int64_t>(config_.flush_interval_s * 1e6));
    for (;;) {
        bool stopping = false;
        {
            std::unique_lock lock(mutex_);
            wake_.wait_for(lock, interval, [this] { return stop_writer_; });
            stopping = stop_writer_;
        }
        if (!write_pending(scratch)) {
            // Stop taking frames; stop() (or the next start()) joins this thread and reports.
            recording_.store(false, std::memory_order_release);
            return;
        }
        if (stopping) return;
    }
}

BvhRepairResult repair_bvh_file(const std::string& path) {
    BvhRepairResult r;
    std::string text;
    {
        std::ifstream in(path, std::ios::binary);
        if (!in) {
            r.error = path + ": " + errno_text(errno);
            return r;
        }
        std::ostringstream ss;
        ss << in.rdbuf();
        text = ss.str();
    }
    std::size_t consumed = 0;
    const auto hierarchy = skeleton::parse_bvh_hierarchy(text, {}, &consumed);
    if (!hierarchy) {
        r.error = path + ": " + hierarchy.error;
        return r;
    }
    const std::size_t values = hierarchy.clip->channels_per_frame;
    // After the hierarchy: MOTION, Frames: N, Frame Time: T, then the lines.
    std::size_t pos = consumed;
    auto next_line = [&](std::string_view& line) {
        if (pos >= text.size()) return false;
        const std::size_t nl = text.find('\n', pos);
        if (nl == std::string::npos) {
            line = std::string_view(text).substr(pos);
            pos = text.size();
            return true;
        }
        line = std::string_view(text).substr(pos, nl - pos);
        pos = nl + 1;
        return true;
    };
    std::string_view line;
    do {
        if (!next_line(line)) {
            r.error = path + ": no MOTION section";
            return r;
        }
    } while (line.find_first_not_of(" \t\r") == std::string_view::npos);
    if (line.substr(0, 6) != "MOTION") {
        r.error = path + ": expected MOTION after the hierarchy";
        return r;
    }
    if (!next_line(line) || line.substr(0, 7) != "Frames:") {
        r.error = path + ": expected \"Frames:\" after MOTION";
        return r;
    }
    r.frames_before = std::strtoull(std::string(line.substr(7)).c_str(), nullptr, 10);
    if (!next_line(line) || line.substr(0, 11) != "Frame Time:") {
        r.error = path + ": expected \"Frame Time:\" after Frames";
        return r;
    }
    const std::string frame_time(line);
    const std::size_t body = pos;
    std::size_t keep_end = body;
    std::vector<double> scratch(values);
    std::size_t line_no = 0;
    while (pos < text.size()) {
        const std::size_t start = pos;
        const bool terminated = text.find('\n', pos) != std::string::npos;
        next_line(line);
        ++line_no;
        std::string_view trimmed = line;
        if (!trimmed.empty() && trimmed.back() == '\r') trimmed.remove_suffix(1);
        const bool blank = trimmed.find_first_not_of(" \t") == std::string_view::npos;
        const bool good = !blank && skeleton::parse_bvh_motion_line(trimmed, scratch).empty();
        if (good && terminated) {
            ++r.frames;
            keep_end = pos;
            continue;
        }
        if (pos >= text.size()) {  // the last line: partial or blank, cut it
            if (!blank) r.bytes_cut = text.size() - start;
            break;
        }
        if (blank) continue;
        r.error = path + ": MOTION line " + std::to_string(line_no) + " is malformed (not the last line)";
        return r;
    }
    const std::string head = text.substr(0, consumed);
    std::string out;
    out.reserve(text.size());
    out += head;
    if (!out.empty() && out.back() != '\n') out += '\n';
    out += "MOTION\nFrames: " + count_digits(r.frames) + "\n" + frame_time + "\n";
    out.append(text, body, keep_end - body);
    const std::string tmp = path + ".repair-tmp";
    {
        std::ofstream o(tmp, std::ios::binary | std::ios::trunc);
        o.write(out.data(), static_cast<std::streamsize>(out.size()));
        if (!o) {
            r.error = tmp + ": write failed";
            return r;
        }
    }
    if (std::rename(tmp.c_str(), path.c_str()) != 0) {
        r.error = "rename " + tmp + ": " + errno_text(errno);
        return r;
    }
    r.ok = true;
    return r;
}

}  // namespace mocap::serve
