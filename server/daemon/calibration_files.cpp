#include "daemon/calibration_files.hpp"

#include <fcntl.h>
#include <spdlog/spdlog.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <filesystem>

#include "core/errno_text.hpp"

namespace mocap::daemon {

namespace fs = std::filesystem;

namespace {

const char* file_kind(mode_t mode) {
    if (S_ISFIFO(mode)) return "a FIFO";
    if (S_ISDIR(mode)) return "a directory";
    if (S_ISSOCK(mode)) return "a socket";
    if (S_ISCHR(mode) || S_ISBLK(mode)) return "a device";
    return "not a regular file";
}

/// Closes the descriptor when it goes out of scope.
struct Fd {
    int fd = -1;
    ~Fd() {
        if (fd >= 0) ::close(fd);
    }
};

// Reading a calibration must never block start-up: a FIFO (or a device) named like a
// calibration file would make a plain open() or read() wait forever for a writer. So the
// file is opened with O_NONBLOCK (which returns at once for a FIFO) and used only if fstat
// says it is a regular file; a regular file ignores O_NONBLOCK.
enum class ReadResult { kMissing, kRead, kError };
ReadResult read_regular_file(const std::string& path, std::string& text, std::string& error) {
    Fd f{::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOCTTY)};
    if (f.fd < 0) {
        if (errno == ENOENT) return ReadResult::kMissing;
        error = errno_text(errno);
        return ReadResult::kError;
    }
    struct stat st {};
    if (::fstat(f.fd, &st) != 0) {
        error = errno_text(errno);
        return ReadResult::kError;
    }
    if (!S_ISREG(st.st_mode)) {
        error = std::string(file_kind(st.st_mode)) + ", not a regular file: skipped";
        return ReadResult::kError;
    }
    char buf[4096];
    for (;;) {
        const ssize_t n = ::read(f.fd, buf, sizeof buf);
        if (n == 0) return ReadResult::kRead;
        if (n < 0) {
            if (errno == EINTR) continue;
            error = errno_text(errno);
            return ReadResult::kError;
        }
        text.append(buf, static_cast<std::size_t>(n));
    }
}

// Writes `text` to a new regular file at `path` (replacing a regular file there). Something
// else at that path (a FIFO would block the writer until a reader came) is refused.
std::string write_regular_file(const std::string& path, const std::string& text) {
    struct stat st {};
    if (::lstat(path.c_str(), &st) == 0 && !S_ISREG(st.st_mode))
        return path + " is " + file_kind(st.st_mode) + ", not a regular file";
    Fd f{::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_NONBLOCK | O_CLOEXEC | O_NOFOLLOW | O_NOCTTY, 0644)};
    if (f.fd < 0) return "cannot write " + path + ": " + errno_text(errno);
    if (::fstat(f.fd, &st) != 0 || !S_ISREG(st.st_mode)) return path + " is not a regular file";
    const char* p = text.data();
    std::size_t left = text.size();
    while (left > 0) {
        const ssize_t n = ::write(f.fd, p, left);
        if (n < 0) {
            if (errno == EINTR) continue;
            return "cannot write " + path + ": " + errno_text(errno);
        }
        p += n;
        left -= static_cast<std::size_t>(n);
    }
    const int fd = f.fd;
    f.fd = -1;
    if (::close(fd) != 0) return "cannot write " + path + ": " + errno_text(errno);
    return {};
}

}  // namespace

std::string CalibrationFiles::path(std::uint32_t subject_id) const {
    return (fs::path(dir_) / ("calibration-subject-" + std::to_string(subject_id) + ".toml")).string();
}

skeleton::StoredCalibration CalibrationFiles::load(const skeleton::BodyModel& model, std::uint32_t subject_id) {
    skeleton::StoredCalibration out;
    out.where = path(subject_id);
    std::string text;
    // Missing: nothing stored (error stays empty). Unreadable: the solver logs "ignoring <where>: <error>".
    if (read_regular_file(out.where, text, out.error) != ReadResult::kRead) return out;
    auto r = skeleton::parse_calibration(model, text);
    out.calibration = std::move(r.calibration);
    out.error = std::move(r.error);
    return out;
}

std::string CalibrationFiles::save(const skeleton::BodyModel& model, std::uint32_t subject_id,
                                   const skeleton::Calibration& calibration) {
    const std::string file = path(subject_id);
    const std::string tmp = file + ".tmp";
    if (std::string err = write_regular_file(tmp, skeleton::serialize_calibration(model, calibration)); !err.empty())
        return err;
    std::error_code ec;
    fs::rename(tmp, file, ec);  // atomic replace: a crash never leaves half a file
    if (ec) return "cannot save calibration to " + file + ": " + ec.message();
    return {};
}

std::unique_ptr<skeleton::CalibrationStore> calibration_files(const std::string& dir) {
    if (dir.empty()) return nullptr;
    return std::make_unique<CalibrationFiles>(dir);
}

void log_to_spdlog(skeleton::LogLevel level, const std::string& line) {
    switch (level) {
        case skeleton::LogLevel::kDebug:
            spdlog::debug("{}", line);
            break;
        case skeleton::LogLevel::kInfo:
            spdlog::info("{}", line);
            break;
        case skeleton::LogLevel::kWarn:
            spdlog::warn("{}", line);
            break;
        case skeleton::LogLevel::kError:
            spdlog::error("{}", line);
            break;
    }
}

}  // namespace mocap::daemon
