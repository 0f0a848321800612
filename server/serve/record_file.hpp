// record_file.hpp — how the file recorders (raw_recorder, bvh_recorder) write: a file only
// ever ends on a whole record, whatever the disk does.
//
// write() may write part of a buffer and then fail (ENOSPC on a disk that fills mid-call), and
// a recorder that appends its next buffer after such a tail leaves a record cut in the middle
// of the file, which no reader can get past. So every write goes to a tracked offset (the end
// of the last whole record), and a failed one truncates the file back to that offset. Should
// even the truncation fail, the next write to the same offset overwrites the partial bytes,
// and the readers skip a cut last record.
//
// FileWriter is the seam: the recorders call the kernel through it, tests inject short
// writes and ENOSPC (tests/serve/record_disk_full_test.cpp).
#pragma once

#include <sys/types.h>

#include <cstddef>
#include <optional>
#include <string>

namespace mocap::serve {

/// The calls a recorder makes on its open file. Implementations: any thread (stateless or
/// locked); a recorder calls them from its writer thread and its control calls.
class FileWriter {
public:
    virtual ~FileWriter() = default;
    /// As pwrite(2): bytes written, or -1 with errno set.
    virtual ssize_t pwrite(int fd, const void* data, std::size_t n, off_t offset) = 0;
    /// As ftruncate(2): 0, or -1 with errno set.
    virtual int ftruncate(int fd, off_t length) = 0;
};

/// The kernel's pwrite/ftruncate.
FileWriter& system_file_writer();

/// Writes all n bytes at `offset`. Returns 0, or the errno of the call that failed (a write
/// that makes no progress counts as EIO); the file is then truncated back to `offset`.
int write_whole(FileWriter& writer, int fd, const char* data, std::size_t n, off_t offset);

// Reading the files of a take or a recording: what is not a regular file (a FIFO planted in
// the store, a device) is refused without blocking the caller.

/// The whole of `path` if it is a regular file of at most max_bytes; nullopt otherwise (a
/// FIFO, a device, a directory are refused without blocking: opened O_NONBLOCK, fstat'ed).
std::optional<std::string> read_regular_file(const std::string& path, std::size_t max_bytes);
/// open(O_RDONLY) of a regular file, never blocking on a FIFO or a device (O_NONBLOCK,
/// then fstat); -1 with errno otherwise (EINVAL: not a regular file). The caller closes it.
int open_regular_file(const std::string& path);

/// ENOSPC or EDQUOT: the disk (or the quota) is full, which freeing space can cure.
bool is_disk_full(int err);

}  // namespace mocap::serve
