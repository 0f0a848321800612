#include "serve/record_file.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>

namespace mocap::serve {

namespace {

class SystemFileWriter final : public FileWriter {
public:
    ssize_t pwrite(int fd, const void* data, std::size_t n, off_t offset) override {
        return ::pwrite(fd, data, n, offset);
    }
    int ftruncate(int fd, off_t length) override { return ::ftruncate(fd, length); }
};

}  // namespace

FileWriter& system_file_writer() {
    static SystemFileWriter writer;
    return writer;
}

int write_whole(FileWriter& writer, int fd, const char* data, std::size_t n, off_t offset) {
    off_t at = offset;
    while (n > 0) {
        const ssize_t w = writer.pwrite(fd, data, n, at);
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) {
            const int err = w < 0 ? errno : EIO;
            // Cut the partial record off; if this fails too, the caller's next write to
            // `offset` overwrites it (see the header).
            while (writer.ftruncate(fd, offset) != 0 && errno == EINTR) {
            }
            return err;
        }
        data += w;
        n -= static_cast<std::size_t>(w);
        at += w;
    }
    return 0;
}

bool is_disk_full(int err) {
    return err == ENOSPC || err == EDQUOT;
}

std::optional<std::string> read_regular_file(const std::string& path, std::size_t max_bytes) {
    // O_NONBLOCK: opening a FIFO for reading would otherwise wait for a writer, for good.
    const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOCTTY);
    if (fd < 0) return std::nullopt;
    struct stat st {};
    std::optional<std::string> text;
    if (::fstat(fd, &st) == 0 && S_ISREG(st.st_mode) && static_cast<std::uint64_t>(st.st_size) <= max_bytes) {
        text.emplace();
        char buf[4096];
        for (;;) {
            const ssize_t n = ::read(fd, buf, sizeof buf);
            if (n < 0 && errno == EINTR) continue;
            if (n < 0 || text->size() + static_cast<std::size_t>(n) > max_bytes) {
                text.reset();
                break;
            }
            if (n == 0) break;
            text->append(buf, static_cast<std::size_t>(n));
        }
    }
    ::close(fd);
    return text;
}

int open_regular_file(const std::string& path) {
    const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOCTTY);
    if (fd < 0) return -1;
    struct stat st {};
    if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
        ::close(fd);
        errno = EINVAL;
        return -1;
    }
    return fd;
}

}  // namespace mocap::serve
