// take_export.cpp — replay of a take into an unlinked file.
#include "daemon/take_export.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>

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
        }
    } cleanup{work};
    for (const std::string& file : entry->meta.calibration) {
        if (!fs::copy_file(fs::path(store.dir(request.name)) / file, fs::path(work) / file, ec))
            return fail(R::kNotFound, "take '" + request.name + "' is gone");
    }
    ReplayOptions options;
    options.files = entry->raw_files;
    options.calibration_dir = work;
    options.bvh_subject = request.subject;
    options.offline = request.offline;
    options.cancel = &cancel;
    const std::string out = work + (request.format == serve::TakeFormat::kBvh ? "/take.bvh" : "/take.csv");
    (request.format == serve::TakeFormat::kBvh ? options.bvh_out : options.angles_out) = out;
    ReplayResult result;
    std::string error;
    if (!run_replay(c, options, &result, &error)) {
        if (cancel.load()) return fail(R::kCancelled, "export cancelled: the daemon is stopping");
        // A file the replay cannot open was deleted since find().
        if (!fs::exists(entry->raw_files.front())) return fail(R::kNotFound, "take '" + request.name + "' is gone");
        return fail(R::kFailed, "export of '" + request.name + "' failed: " + error);
    }
    const int fd = ::open(out.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) return fail(R::kFailed, "export of '" + request.name + "' wrote no file");
    return R{R::kOk, {}, fd};
}

}  // namespace mocap::daemon
