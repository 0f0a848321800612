// take_store.hpp — where takes live on disk and what is known about them (docs/client-protocol.md,
// "Takes"; docs/outputs.md, "Takes").
//
// A take is one directory <root>/<name>/ holding
//   take.json                 the metadata sidecar (TakeMeta below, encode_take_json)
//   raw-<UTC>-0.mocapraw      the raw recording (serve/raw_recorder.hpp, no rotation)
//   calibration-subject-<id>.toml   the calibrations in use when the take started (copies)
// Names are [A-Za-z0-9][A-Za-z0-9._-]{0,63} (valid_take_name): never "." or "..", never a
// slash, so a name taken from a URL cannot leave <root>. Entries whose name starts with '.'
// are the store's own (a take being deleted) and are never listed.
//
// Crash safety: the sidecar is replaced whole (write_file_atomically: temp file, fsync,
// rename, fsync of the directory), so it is always the old or the new version, never half
// of one; it is written when a take starts (no stop time) and again when it stops. A take
// whose daemon died keeps its start sidecar and a raw file that reads up to its last
// whole record (at most the last flush interval lost): it lists with "stopped": false.
// Deleting renames the directory to a hidden name first (one atomic step: the take is gone
// from every listing at once), then removes its files; a download that already opened a
// file keeps reading it (the kernel frees it on close). A hidden folder left by a daemon
// that died in between is removed at the next start (remove_unfinished_deletes).
//
// Listing: list() keeps every take's entry in memory (~1 KiB each) and reads the sidecars
// again only after this store created, saved or removed a take, or <root>'s mtime changed
// (a take directory added or removed by hand). A sidecar edited by hand in place shows after
// the next such change. The recording take's raw_bytes are read afresh on every call.
//
// Threads: every member may be called from any thread; list/find/remove/mark_recording
// serialise on one mutex, file I/O included (a take directory holds a handful of files).
#pragma once

#include <cstdint>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace mocap::serve {

/// Longest take name and longest notes accepted.
inline constexpr std::size_t kMaxTakeNameBytes = 64;
inline constexpr std::size_t kMaxTakeNotesBytes = 4096;

/// [A-Za-z0-9][A-Za-z0-9._-]{0,63}: safe as one path component and in a URL.
bool valid_take_name(std::string_view name);

struct TakeMeta {
    std::string name;
    std::int64_t start_us = 0;             ///< wall clock (CLOCK_REALTIME µs) when the take started
    std::int64_t stop_us = 0;              ///< 0 = not stopped: recording, or its daemon died
    std::vector<std::uint32_t> subjects;   ///< subjects with samples in the take (known at stop)
    std::vector<std::string> calibration;  ///< calibration files copied into the take
    std::string filter;                    ///< the daemon's [filter] name when the take started
    std::string notes;
    std::uint64_t samples = 0;       ///< samples written (known at stop)
    std::uint64_t samples_lost = 0;  ///< dropped or lost by the recorder (known at stop)
    std::string loss;                ///< why samples were lost ("" = none was): the first write failure, or the ring
    bool operator==(const TakeMeta&) const = default;
};

/// The sidecar's JSON text (one object, keys as the fields above, "start"/"stop" also as
/// RFC 3339 UTC for people).
std::string encode_take_json(const TakeMeta& meta);
/// Parses a sidecar; nullopt + error on anything that is not one (a wrong type, a bad name).
std::optional<TakeMeta> decode_take_json(std::string_view text, std::string* error);

/// Largest sidecar read (notes are at most 4096 bytes; a sidecar is ~1 KiB).
inline constexpr std::size_t kMaxSidecarBytes = std::size_t{64} * 1024;

/// Writes `text` to `path` so that a crash leaves either the old file or the new one:
/// <path>.tmp, fsync, rename over `path`, fsync of the directory. 0, or the errno of the
/// failed step (the temp file is removed then).
int write_file_atomically(const std::string& path, std::string_view text);

struct TakeEntry {
    TakeMeta meta;
    std::vector<std::string> raw_files;  ///< paths, in recording order
    std::uint64_t raw_bytes = 0;
    bool recording = false;  ///< the take being recorded now
};

class TakeStore {
public:
    /// `root`: the directory holding the takes (created on first use).
    explicit TakeStore(std::string root);

    [[nodiscard]] const std::string& root() const { return root_; }
    /// <root>/<name> (the name must be valid).
    [[nodiscard]] std::string dir(std::string_view name) const;

    /// Creates the take's directory and writes its first sidecar. False + error when the
    /// name is invalid or taken, or the disk refuses (nothing is left behind then).
    bool create(const TakeMeta& meta, std::string* error);
    /// Replaces the sidecar of an existing take.
    bool save(const TakeMeta& meta, std::string* error);
    /// Every take, by start time then name. A directory without a readable sidecar is skipped.
    /// Served from a cache of the sidecars (see below): a call reads no sidecar unless a
    /// take was created, saved or removed since, through this store or in the directory.
    [[nodiscard]] std::vector<TakeEntry> list() const;
    /// Takes [offset, offset + limit) of list(), and how many there are in all.
    struct Page {
        std::vector<TakeEntry> takes;
        std::size_t total = 0;
    };
    [[nodiscard]] Page list_page(std::size_t offset, std::size_t limit) const;
    /// Sidecars read by list()/list_page() since construction (a test's view of the cache).
    [[nodiscard]] std::uint64_t sidecars_read() const;
    [[nodiscard]] std::optional<TakeEntry> find(std::string_view name) const;

    enum class Removal { kRemoved, kNotFound, kRecording, kFailed };
    /// Deletes a take (see the header). A take being recorded is refused.
    Removal remove(std::string_view name, std::string* error);

    /// The take being recorded ("" = none): remove() refuses it, list() marks it.
    void mark_recording(std::string name);

    /// At start: removes the `.deleting-*` directories a delete left when the daemon died
    /// between its rename and the removal. Only those, only directly in the root, never
    /// through a symbolic link (one of that name is left alone, as its target is). Logs
    /// what it removed; returns how many.
    std::size_t remove_unfinished_deletes();

private:
    std::optional<TakeEntry> load(const std::string& name) const;  // mutex_ held
    /// The cache, reloaded when invalid or when <root>'s mtime moved (a take directory
    /// created or removed by another process); the recording take's raw size refreshed.
    const std::vector<TakeEntry>& cached() const;  // mutex_ held

    std::string root_;
    mutable std::mutex mutex_;
    std::string recording_;    // guarded
    std::uint64_t trash_ = 0;  // guarded: suffix of hidden names
    // The listing cache (guarded): every take, sorted; invalidated by create/save/remove.
    mutable std::vector<TakeEntry> cache_;
    mutable bool cache_valid_ = false;
    mutable std::int64_t cache_root_mtime_ns_ = -1;
    mutable std::uint64_t sidecars_read_ = 0;
};

}  // namespace mocap::serve
