#include "serve/raw_recorder.hpp"

#include <fcntl.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <ctime>

#include "core/errno_text.hpp"
#include "mocap/v1/recording.pb.h"

namespace mocap::serve {

namespace {

constexpr std::uint32_t kFormatVersion = 1;
constexpr std::size_t kMaxRecordBytes = 1u << 16;  // a sample record is ~100 bytes

void append_varint(std::uint64_t v, std::string& out) {
    while (v >= 0x80) {
        out += static_cast<char>((v & 0x7F) | 0x80);
        v >>= 7;
    }
    out += static_cast<char>(v);
}

void append_record(const v1::RawRecord& record, std::string& out) {
    const std::size_t n = record.ByteSizeLong();
    append_varint(n, out);
    const std::size_t at = out.size();
    out.resize(at + n);
    record.SerializeWithCachedSizesToArray(reinterpret_cast<std::uint8_t*>(out.data() + at));
}

std::string utc_stamp(std::int64_t us) {
    const std::time_t t = static_cast<std::time_t>(us / 1'000'000);
    std::tm tm{};
    gmtime_r(&t, &tm);
    char buf[32];
    std::strftime(buf, sizeof buf, "%Y%m%d-%H%M%S", &tm);
    return buf;
}

}  // namespace

void append_raw_sample_record(const SegmentSample& s, std::string& out) {
    v1::RawRecord record;
    auto* r = record.mutable_sample();
    r->set_subject_id(s.subject_id);
    r->set_node_id(s.node_id);
    r->set_sync(s.sync);
    r->set_t_us(s.imu.t_us);
    r->set_imu_flags(s.imu.flags);
    if (s.has_node_quat) {
        for (const double q : s.node_q_wxyz)
            r->add_node_q_wxyz(static_cast<float>(q));
    } else {
        for (int i = 0; i < 3; ++i) {
            r->add_gyro_rad_s(static_cast<float>(s.imu.gyro_rad_s[static_cast<std::size_t>(i)]));
            r->add_accel_m_s2(static_cast<float>(s.imu.accel_m_s2[static_cast<std::size_t>(i)]));
            r->add_mag_ut(static_cast<float>(s.imu.mag_ut[static_cast<std::size_t>(i)]));
        }
    }
    r->set_sink_send_us(s.times.sink_send_us);
    r->set_received_us(s.times.received_us);
    append_record(record, out);
}

RawRecorder::RawRecorder(RawRecorderConfig config, const Clock& clock, FileWriter& writer)
    : config_(std::move(config)), clock_(clock), file_writer_(writer), ring_(config_.ring_capacity) {
    group_.add("samples_recorded", recorded_);
    group_.add("samples_dropped", dropped_);
    group_.add("samples_lost", lost_);
    group_.add("bytes_written", bytes_);
    group_.add("files_opened", files_);
    group_.add("write_errors", write_errors_);
    group_.add("disk_full", disk_full_);
    group_.add("write_pauses", pauses_);
    buffer_.reserve(std::min<std::size_t>(config_.max_buffer_bytes, 1u << 20));
}

RawRecorder::~RawRecorder() {
    stop();
}

bool RawRecorder::start(std::string* error) {
    series_stamp_ = utc_stamp(clock_.now_us());
    if (open_next(error) != 0) {
        *error = "raw recording: " + *error;
        return false;
    }
    writer_ = std::thread([this] {
        pthread_setname_np(pthread_self(), "mocap-rawrec");
        writer_loop();
    });
    return true;
}

void RawRecorder::stop() {
    if (!writer_.joinable()) return;
    stop_.store(true, std::memory_order_release);
    writer_.join();
}

bool RawRecorder::push(const SegmentSample& sample) noexcept {
    if (ring_.try_push(sample)) return true;
    dropped_.add();
    return false;
}

std::string RawRecorder::current_path() const {
    std::lock_guard lock(path_mutex_);
    return path_;
}

int RawRecorder::open_next(std::string* error) {
    char name[64];
    std::snprintf(name, sizeof name, "/raw-%s-%u.mocapraw", series_stamp_.c_str(), file_index_);
    const std::string path = config_.directory + name;
    const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0640);
    if (fd < 0) {
        const int err = errno;
        *error = "cannot create " + path + ": " + errno_text(err);
        return err;
    }
    const std::int64_t opened_us = clock_.now_us();
    std::string head(kRawMagic, sizeof kRawMagic);
    v1::RawRecord header;
    header.mutable_header()->set_format_version(kFormatVersion);
    header.mutable_header()->set_created_us(opened_us);
    header.mutable_header()->set_producer("mocapd");
    header.mutable_header()->set_file_index(file_index_);
    append_record(header, head);
    if (const int err = write_whole(file_writer_, fd, head.data(), head.size(), 0); err != 0) {
        // A file without its header is no recording: remove it, and try this name again later.
        ::close(fd);
        ::unlink(path.c_str());
        *error = "cannot write " + path + ": " + errno_text(err);
        return err;
    }
    fd_ = fd;
    file_bytes_ = head.size();
    bytes_.add(head.size());
    file_opened_us_ = opened_us;
    ++file_index_;
    files_.add();
    {
        std::lock_guard lock(path_mutex_);
        path_ = path;
    }
    spdlog::info("raw recording: writing {}", path);
    return 0;
}

void RawRecorder::buffer_sample(const SegmentSample& s) {
    // The bound holds while writes fail; in normal running a flush interval's worth of
    // samples is far below it.
    if (buffer_.size() >= config_.max_buffer_bytes) {
        lost_.add();
        ++lost_in_pause_;
        return;
    }
    append_raw_sample_record(s, buffer_);
    ++buffer_samples_;
}

bool RawRecorder::flush_buffer() {
    if (buffer_.empty()) return true;
    if (fd_ < 0) return false;
    if (const int err = write_whole(file_writer_, fd_, buffer_.data(), buffer_.size(), static_cast<off_t>(file_bytes_));
        err != 0) {
        on_failure(err, "write " + current_path());
        return false;  // the buffer is kept (bounded) for the retry
    }
    bytes_.add(buffer_.size());
    file_bytes_ += buffer_.size();
    recorded_.add(buffer_samples_);
    buffer_.clear();
    buffer_samples_ = 0;
    return true;
}

void RawRecorder::on_failure(int err, const std::string& what) {
    write_errors_.add();
    if (first_failure_.empty()) first_failure_ = what + " failed: " + errno_text(err);
    const std::int64_t now = clock_.now_us();
    if (!paused_.load(std::memory_order_relaxed)) {
        // One line per episode, with the reason; the retries that follow are only counted.
        paused_.store(true, std::memory_order_relaxed);
        pauses_.add();
        if (is_disk_full(err)) disk_full_.add();
        lost_in_pause_ = 0;
        retry_delay_us_ = static_cast<std::int64_t>(config_.retry_min_s * 1e6);
        spdlog::error(
            "raw recording: {} failed: {}; recording paused, the file ends at its last whole record; up to {} "
            "bytes of samples are kept, the rest counted as lost (raw_record.samples_lost); retrying every {}-{} s",
            what, errno_text(err), config_.max_buffer_bytes, config_.retry_min_s, config_.retry_max_s);
    } else {
        retry_delay_us_ = std::min(retry_delay_us_ * 2, static_cast<std::int64_t>(config_.retry_max_s * 1e6));
    }
    retry_at_us_ = now + retry_delay_us_;
}

void RawRecorder::retry() {
    if (fd_ < 0) {
        std::string error;
        if (const int err = open_next(&error); err != 0) {
            on_failure(err, error);
            return;
        }
    }
    if (!flush_buffer()) return;
    paused_.store(false, std::memory_order_relaxed);
    spdlog::info("raw recording: writing {} again; {} samples were lost while paused", current_path(), lost_in_pause_);
}

void RawRecorder::close_file() {
    if (fd_ < 0) return;
    if (config_.fsync_on_rotate) ::fsync(fd_);
    ::close(fd_);
    fd_ = -1;
    std::lock_guard lock(path_mutex_);
    path_.clear();
}

void RawRecorder::writer_loop() {
    const auto flush_us = static_cast<std::int64_t>(config_.flush_interval_s * 1e6);
    const auto rotate_us = static_cast<std::int64_t>(config_.rotate_s * 1e6);
    std::int64_t last_flush_us = clock_.now_us();
    SegmentSample s;
    for (;;) {
        // Read stop first: after it is seen, one more drain empties the ring for good
        // (the producer stopped before stop() was called).
        const bool stopping = stop_.load(std::memory_order_acquire);
        std::size_t n = 0;
        while (ring_.try_pop(s)) {
            buffer_sample(s);
            ++n;
        }
        const std::int64_t now = clock_.now_us();
        if (stopping) {
            // A paused recorder tries once more: the disk may have room again.
            if (paused_.load(std::memory_order_relaxed)) {
                retry();
            } else {
                flush_buffer();
            }
            lost_.add(buffer_samples_);  // what the file could not take
            buffer_.clear();
            buffer_samples_ = 0;
            close_file();
            return;
        }
        if (paused_.load(std::memory_order_relaxed)) {
            if (now >= retry_at_us_) retry();
        } else if (fd_ >= 0 && ((config_.rotate_bytes != 0 && file_bytes_ + buffer_.size() >= config_.rotate_bytes) ||
                                (rotate_us > 0 && now - file_opened_us_ >= rotate_us))) {
            // Rotate only once this file holds everything so far; a failed write pauses.
            if (flush_buffer()) {
                close_file();
                std::string error;
                if (const int err = open_next(&error); err != 0) on_failure(err, error);
            }
        } else if (now - last_flush_us >= flush_us) {
            flush_buffer();
            last_flush_us = now;
        }
        if (n == 0) std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
}

bool RawRecordingReader::open(const std::string& path, std::string* error) {
    file_.reset();
    const int fd = open_regular_file(path);
    if (fd < 0) {
        *error = path + ": " + (errno == EINVAL ? std::string("not a regular file") : errno_text(errno));
        return false;
    }
    file_.reset(::fdopen(fd, "rb"));
    if (!file_) {
        *error = path + ": " + errno_text(errno);
        ::close(fd);
        return false;
    }
    char magic[sizeof kRawMagic];
    if (std::fread(magic, 1, sizeof magic, file_.get()) != sizeof magic ||
        std::memcmp(magic, kRawMagic, sizeof magic) != 0) {
        *error = path + ": not a mocapd raw recording (bad magic)";
        return false;
    }
    return true;
}

bool RawRecordingReader::open_records(std::string records, std::string* error) {
    file_.reset();
    truncated_ = false;
    truncation_.clear();
    memory_ = std::move(records);
    if (memory_.empty()) {
        *error = "no records";
        return false;
    }
    // A stream over the buffer: the file path's record parsing, truncation handling included.
    file_.reset(::fmemopen(memory_.data(), memory_.size(), "rb"));
    if (!file_) {
        *error = "fmemopen: " + errno_text(errno);
        return false;
    }
    return true;
}

void RawRecordingReader::cut_tail(const std::string& what) {
    truncated_ = true;
    truncation_ = what + " after sample " + std::to_string(samples_) + ", skipped";
}

int RawRecordingReader::next(SegmentSample& out, std::string* error) {
    v1::RawRecord record;
    for (;;) {
        std::uint64_t len = 0;
        int shift = 0;
        for (;;) {
            const int c = std::fgetc(file_.get());
            if (c == EOF) {
                if (shift != 0) cut_tail("a cut record length");
                return 0;
            }
            len |= static_cast<std::uint64_t>(c & 0x7F) << shift;
            shift += 7;
            if ((c & 0x80) == 0) break;
            if (shift > 28) {
                *error = "record length varint too long";
                return -1;
            }
        }
        if (len > kMaxRecordBytes) {
            *error = "record of " + std::to_string(len) + " bytes exceeds the limit";
            return -1;
        }
        record_.resize(len);
        if (const std::size_t got = std::fread(record_.data(), 1, len, file_.get()); got != len) {
            cut_tail("a cut record (" + std::to_string(got) + " of " + std::to_string(len) + " bytes)");
            return 0;
        }
        if (!record.ParseFromString(record_)) {
            // The last record of a file may be garbage a crash left (a tail the kernel had
            // sized but not written); anywhere else it is corruption.
            if (std::fgetc(file_.get()) == EOF) {
                cut_tail("an unparseable last record of " + std::to_string(len) + " bytes");
                return 0;
            }
            *error = "unparseable record after sample " + std::to_string(samples_);
            return -1;
        }
        if (!record.has_sample()) continue;  // header (or a newer record kind)
        const auto& r = record.sample();
        out = SegmentSample{};
        out.subject_id = r.subject_id();
        out.node_id = static_cast<std::uint8_t>(r.node_id());
        out.sync = r.sync();
        out.imu.t_us = r.t_us();
        out.imu.flags = static_cast<std::uint8_t>(r.imu_flags());
        if (r.node_q_wxyz_size() == 4) {
            out.has_node_quat = true;
            for (int i = 0; i < 4; ++i)
                out.node_q_wxyz[static_cast<std::size_t>(i)] = r.node_q_wxyz(i);
        } else if (r.gyro_rad_s_size() == 3 && r.accel_m_s2_size() == 3 && r.mag_ut_size() == 3) {
            for (int i = 0; i < 3; ++i) {
                const auto k = static_cast<std::size_t>(i);
                out.imu.gyro_rad_s[k] = r.gyro_rad_s(i);
                out.imu.accel_m_s2[k] = r.accel_m_s2(i);
                out.imu.mag_ut[k] = r.mag_ut(i);
            }
        } else {
            *error = "sample " + std::to_string(samples_) + " has neither 3+3+3 IMU values nor a quaternion";
            return -1;
        }
        out.times.sink_send_us = r.sink_send_us();
        out.times.received_us = r.received_us();
        ++samples_;
        return 1;
    }
}

}  // namespace mocap::serve
