#include "serve/record_file.hpp"

#include <unistd.h>

#include <cerrno>

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

}  // namespace mocap::serve
