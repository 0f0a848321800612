// take_export.cpp — replay of a take into a memfd.
#include "daemon/take_export.hpp"

#include <fcntl.h>
#include <malloc.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>

#include "core/errno_text.hpp"
#include "daemon/replay.hpp"
#include "filter/filter_factory.hpp"

namespace mocap::daemon {

namespace fs = std::filesystem;

namespace {

std::atomic<std::uint64_t> next_export{0};

/// Export directories of an earlier process (one that crashed mid-export); this process
/// removes its own.
void remove_stale_exports(const std::string& root) {
    const std::string mine = ".export-" + std::to_string(::getpid()) + "-";
    std::error_code ec;
    for (const auto& d : fs::directory_iterator(root, ec)) {
        const std::string name = d.path().filename().string();
        if (name.starts_with(".export-") && !name.starts_with(mine)) fs::remove_all(d.path(), ec);
    }
}

std::string subject_list(const std::vector<std::uint32_t>& subjects) {
    std::string out;
    for (const std::uint32_t id : subjects)
        out += (out.empty() ? "" : ", ") + std::to_string(id);
    return out;
}

}  // namespace

serve::TakeExportResult export_take(const DaemonConfig& config, const serve::TakeStore& store,
                                    const serve::TakeExportRequest& request, const std::atomic<bool>& cancel) {
    using R = serve::TakeExportResult;
    const auto fail = [](R::Status status, std::string error) { return R{status, std::move(error), -1}; };
    DaemonConfig c = config;
    if (!request.filter.empty()) {
        const auto names = filter::filter_names();
        if (std::find(names.begin(), names.end(), request.filter) == names.end()) {
            std::string known;
            for (const auto n : names)
                known += (known.empty() ? "" : ", ") + std::string(n);
            return fail(R::kBadRequest, "unknown filter '" + request.filter + "' (known: " + known + ")");
        }
        c.filter_name = request.filter;
        c.filter_params.clear();  // they belong to the configured filter
        for (auto& s : c.segments)
            s.filter.clear();
    }
    const auto entry = store.find(request.name);
    if (!entry) return fail(R::kNotFound, "no take '" + request.name + "'");
    if (entry->raw_files.empty()) return fail(R::kNotFound, "take '" + request.name + "' has no raw file");
    const auto& subjects = entry->meta.subjects;
    if (request.format == serve::TakeFormat::kBvh && request.subject != 0 && !subjects.empty() &&
        std::find(subjects.begin(), subjects.end(), request.subject) == subjects.end()) {
        return fail(R::kNotFound, "take '" + request.name + "' has no subject " + std::to_string(request.subject) +
                                      " (subjects: " + subject_list(subjects) + ")");
    }
    if (request.offline) {
        const std::uint64_t estimate = offline_export_estimate_bytes(entry->raw_bytes);
        const std::uint64_t limit = std::uint64_t{config.offline_export_max_mb} << 20;
        if (estimate > limit) {
            return fail(R::kTooLarge,
                        "the offline re-solve of '" + request.name + "' would hold about " +
                            std::to_string(estimate >> 20) + " MiB (" + std::to_string(kOfflineBytesPerRawByte) +
                            "x its " + std::to_string(entry->raw_bytes >> 20) + " MiB raw file), above " +
                            "[outputs] offline_export_max_mb = " + std::to_string(config.offline_export_max_mb) +
                            "; download it without offline=1, or run mocapd --replay --offline on it");
        }
    }
    if (cancel.load()) return fail(R::kCancelled, "export cancelled");

    const std::string work =
        store.root() + "/.export-" + std::to_string(::getpid()) + "-" + std::to_string(next_export.fetch_add(1));
    remove_stale_exports(store.root());
    std::error_code ec;
    if (!fs::create_directory(work, ec)) return fail(R::kFailed, "cannot create " + work + ": " + ec.message());
    struct Cleanup {
        std::string dir;
        ~Cleanup() {
            std::error_code ignored;
            fs::remove_all(dir, ignored);
            // A re-solve's buffers (the offline one holds the whole take) go back to the
            // system, not only to malloc's free lists (docs/reliability.md, "Export memory").
            ::malloc_trim(0);
        }
    } cleanup{work};
    for (const std::string& file : entry->meta.calibration) {
        if (!fs::copy_file(fs::path(store.dir(request.name)) / file, fs::path(work) / file, ec))
            return fail(R::kNotFound, "take '" + request.name + "' is gone");
    }
    // The export lives in memory, never on record_dir's disk, which a running take needs
    // (the web endpoint charges it to its export budget, serve/take_export_budget.hpp).
    const bool bvh = request.format == serve::TakeFormat::kBvh;
    const int out = ::memfd_create(bvh ? "mocap-export.bvh" : "mocap-export.csv", MFD_CLOEXEC);
    if (out < 0) return fail(R::kFailed, "export of '" + request.name + "': memfd_create: " + errno_text(errno));
    ReplayOptions options;
    // The output's growth is charged as it is written (request.reserve: the web endpoint's
    // export budget), so an export is refused for what it really holds, not for its take's
    // size. The BVH writer flushes every record_flush_interval_s: a tenth of a second at most
    // here, so that what the budget sees lags what the export holds by little.
    std::string over;  // reserve() refused: why
    if (request.reserve) {
        c.record_flush_interval_s = std::min(c.record_flush_interval_s, 0.1);
        options.progress = [&](std::string* why) {
            struct stat st {};
            if (::fstat(out, &st) != 0 || request.reserve(static_cast<std::uint64_t>(st.st_size), &over)) return true;
            *why = over;
            return false;
        };
    }
    options.files = entry->raw_files;
    options.calibration_dir = work;
    options.bvh_subject = request.subject;
    options.offline = request.offline;
    options.cancel = &cancel;
    (bvh ? options.bvh_out_fd : options.angles_out_fd) = out;
    (bvh ? options.bvh_out : options.angles_out) = "the export of '" + request.name + "'";
    ReplayResult result;
    std::string error;
    if (!run_replay(c, options, &result, &error)) {
        ::close(out);
        if (!over.empty()) return fail(R::kTooLarge, over);
        if (cancel.load()) return fail(R::kCancelled, "export cancelled");
        // A file the replay cannot open was deleted since find().
        if (!fs::exists(entry->raw_files.front())) return fail(R::kNotFound, "take '" + request.name + "' is gone");
        return fail(R::kFailed, "export of '" + request.name + "' failed: " + error);
    }
    if (bvh && request.subject != 0 && result.bvh_frames == 0) {
        ::close(out);
        return fail(R::kNotFound,
                    "take '" + request.name + "' has no frame of subject " + std::to_string(request.subject));
    }
    if (::lseek(out, 0, SEEK_SET) != 0) {
        ::close(out);
        return fail(R::kFailed, "export of '" + request.name + "': " + errno_text(errno));
    }
    return R{R::kOk, {}, out};
}

std::uint64_t offline_export_estimate_bytes(std::uint64_t raw_bytes) {
    return raw_bytes * kOfflineBytesPerRawByte;
}

}  // namespace mocap::daemon
