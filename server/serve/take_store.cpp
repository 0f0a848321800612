// take_store.cpp — take directories, the sidecar's JSON, the atomic file replacement.
#include "serve/take_store.hpp"

#include <fcntl.h>
#include <spdlog/spdlog.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <ctime>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "core/errno_text.hpp"
#include "serve/record_file.hpp"

namespace mocap::serve {

namespace fs = std::filesystem;

namespace {

constexpr const char* kSidecar = "take.json";

bool name_char(char c, bool first) {
    const bool alnum = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9');
    return alnum || (!first && (c == '.' || c == '_' || c == '-'));
}

std::string rfc3339(std::int64_t us) {
    if (us <= 0) return "";
    const auto t = static_cast<std::time_t>(us / 1'000'000);
    std::tm tm{};
    gmtime_r(&t, &tm);
    char buf[40];
    std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%S", &tm);
    char out[48];
    std::snprintf(out, sizeof out, "%s.%06lldZ", buf, static_cast<long long>(us % 1'000'000));
    return out;
}

int fsync_path(const std::string& path, int flags) {
    const int fd = ::open(path.c_str(), flags | O_CLOEXEC);
    if (fd < 0) return errno;
    const int err = ::fsync(fd) == 0 ? 0 : errno;
    ::close(fd);
    return err;
}

void scan_raw_files(const std::string& d, TakeEntry& e) {
    e.raw_files.clear();
    e.raw_bytes = 0;
    std::error_code ec;
    for (const auto& f : fs::directory_iterator(d, ec)) {
        // Only regular files: a FIFO or a device would block whoever opens it.
        if (f.path().extension() != ".mocapraw" || !f.is_regular_file(ec)) continue;
        e.raw_files.push_back(f.path().string());
        const std::uintmax_t n = f.file_size(ec);
        if (!ec) e.raw_bytes += n;
    }
    // raw-<UTC>-<index>: the names sort in recording order.
    std::sort(e.raw_files.begin(), e.raw_files.end());
}

}  // namespace

bool valid_take_name(std::string_view name) {
    if (name.empty() || name.size() > kMaxTakeNameBytes) return false;
    for (std::size_t i = 0; i < name.size(); ++i) {
        if (!name_char(name[i], i == 0)) return false;
    }
    return true;
}

std::string encode_take_json(const TakeMeta& m) {
    const nlohmann::ordered_json j{{"name", m.name},
                                   {"start_us", m.start_us},
                                   {"start", rfc3339(m.start_us)},
                                   {"stop_us", m.stop_us},
                                   {"stop", rfc3339(m.stop_us)},
                                   {"subjects", m.subjects},
                                   {"calibration", m.calibration},
                                   {"filter", m.filter},
                                   {"notes", m.notes},
                                   {"samples", m.samples},
                                   {"samples_lost", m.samples_lost},
                                   {"loss", m.loss}};
    // Notes come from a client: invalid UTF-8 becomes U+FFFD rather than an exception.
    return j.dump(2, ' ', false, nlohmann::ordered_json::error_handler_t::replace) + "\n";
}

std::optional<TakeMeta> decode_take_json(std::string_view text, std::string* error) {
    const auto j = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
    if (!j.is_object()) {
        *error = "not a JSON object";
        return std::nullopt;
    }
    TakeMeta m;
    try {
        m.name = j.at("name").get<std::string>();
        m.start_us = j.at("start_us").get<std::int64_t>();
        m.stop_us = j.value("stop_us", std::int64_t{0});
        for (const auto& id : j.value("subjects", nlohmann::json::array())) {
            // nlohmann would wrap -1 into a uint32: subject ids are checked by hand.
            if (!id.is_number_unsigned() || id.get<std::uint64_t>() > UINT32_MAX) {
                *error = "subjects: not a subject id: " + id.dump();
                return std::nullopt;
            }
            m.subjects.push_back(id.get<std::uint32_t>());
        }
        m.calibration = j.value("calibration", std::vector<std::string>{});
        m.filter = j.value("filter", std::string{});
        m.notes = j.value("notes", std::string{});
        m.samples = j.value("samples", std::uint64_t{0});
        m.samples_lost = j.value("samples_lost", std::uint64_t{0});
        m.loss = j.value("loss", std::string{});
    } catch (const nlohmann::json::exception& e) {
        *error = e.what();
        return std::nullopt;
    }
    if (!valid_take_name(m.name)) {
        *error = "invalid take name";
        return std::nullopt;
    }
    return m;
}

int write_file_atomically(const std::string& path, std::string_view text) {
    const std::string tmp = path + ".tmp";
    const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0640);
    if (fd < 0) return errno;
    int err = 0;
    for (std::size_t done = 0; done < text.size() && err == 0;) {
        const ssize_t w = ::write(fd, text.data() + done, text.size() - done);
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) {
            err = w < 0 ? errno : EIO;
            break;
        }
        done += static_cast<std::size_t>(w);
    }
    if (err == 0 && ::fsync(fd) != 0) err = errno;
    if (::close(fd) != 0 && err == 0) err = errno;
    if (err == 0 && ::rename(tmp.c_str(), path.c_str()) != 0) err = errno;
    if (err != 0) {
        ::unlink(tmp.c_str());
        return err;
    }
    // The rename itself is durable only once the directory is.
    return fsync_path(fs::path(path).parent_path().string(), O_RDONLY | O_DIRECTORY);
}

TakeStore::TakeStore(std::string root) : root_(std::move(root)) {}

std::string TakeStore::dir(std::string_view name) const {
    return root_ + "/" + std::string(name);
}

std::size_t TakeStore::remove_unfinished_deletes() {
    std::lock_guard lock(mutex_);
    std::error_code ec;
    std::vector<fs::path> left;
    for (fs::directory_iterator it(root_, ec), end; !ec && it != end; it.increment(ec)) {
        // symlink_status: a link of that name is not a directory of ours, whatever it points at.
        if (it->path().filename().string().rfind(".deleting-", 0) == 0 && fs::is_directory(it->symlink_status()))
            left.push_back(it->path());
    }
    std::size_t removed = 0;
    for (const fs::path& p : left) {
        fs::remove_all(p, ec);  // removes links inside, never what they point at
        if (ec) {
            spdlog::warn("takes: cannot remove {}, left by a delete that did not finish: {}", p.string(), ec.message());
        } else {
            ++removed;
        }
    }
    if (removed > 0) spdlog::info("takes: removed {} folder(s) left by deletes that did not finish", removed);
    return removed;
}

bool TakeStore::create(const TakeMeta& meta, std::string* error) {
    if (!valid_take_name(meta.name)) {
        *error = "invalid take name '" + meta.name + "': expected [A-Za-z0-9][A-Za-z0-9._-]{0,63}";
        return false;
    }
    std::lock_guard lock(mutex_);
    std::error_code ec;
    fs::create_directories(root_, ec);
    const std::string d = dir(meta.name);
    if (::mkdir(d.c_str(), 0750) != 0) {
        const int err = errno;
        *error = err == EEXIST ? "take '" + meta.name + "' exists" : "cannot create " + d + ": " + errno_text(err);
        return false;
    }
    cache_valid_ = false;
    if (const int err = write_file_atomically(d + "/" + kSidecar, encode_take_json(meta)); err != 0) {
        fs::remove_all(d, ec);
        *error = "cannot write " + d + "/" + kSidecar + ": " + errno_text(err);
        return false;
    }
    return true;
}

bool TakeStore::save(const TakeMeta& meta, std::string* error) {
    std::lock_guard lock(mutex_);
    cache_valid_ = false;
    const std::string path = dir(meta.name) + "/" + kSidecar;
    if (const int err = write_file_atomically(path, encode_take_json(meta)); err != 0) {
        *error = "cannot write " + path + ": " + errno_text(err);
        return false;
    }
    return true;
}

std::optional<TakeEntry> TakeStore::load(const std::string& name) const {
    const std::string d = dir(name);
    const auto text = read_regular_file(d + "/" + kSidecar, kMaxSidecarBytes);
    if (!text) return std::nullopt;
    std::string error;
    auto meta = decode_take_json(*text, &error);
    if (!meta || meta->name != name) return std::nullopt;
    TakeEntry e;
    e.meta = std::move(*meta);
    e.recording = name == recording_;
    scan_raw_files(d, e);
    return e;
}

const std::vector<TakeEntry>& TakeStore::cached() const {
    struct stat st {};
    const std::int64_t mtime_ns =
        ::stat(root_.c_str(), &st) == 0 ? std::int64_t{st.st_mtim.tv_sec} * 1'000'000'000 + st.st_mtim.tv_nsec : -1;
    if (!cache_valid_ || mtime_ns != cache_root_mtime_ns_) {
        cache_.clear();
        std::error_code ec;
        for (const auto& d : fs::directory_iterator(root_, ec)) {
            const std::string name = d.path().filename().string();
            if (!valid_take_name(name) || !d.is_directory(ec)) continue;
            ++sidecars_read_;
            if (auto e = load(name)) cache_.push_back(std::move(*e));
        }
        std::sort(cache_.begin(), cache_.end(), [](const TakeEntry& a, const TakeEntry& b) {
            return a.meta.start_us != b.meta.start_us ? a.meta.start_us < b.meta.start_us : a.meta.name < b.meta.name;
        });
        cache_valid_ = true;
        cache_root_mtime_ns_ = mtime_ns;
    }
    for (TakeEntry& e : cache_) {
        e.recording = !recording_.empty() && e.meta.name == recording_;
        if (!e.recording) continue;
        scan_raw_files(dir(e.meta.name), e);  // it grows, and its file appears after its sidecar
    }
    return cache_;
}

std::vector<TakeEntry> TakeStore::list() const {
    std::lock_guard lock(mutex_);
    return cached();
}

TakeStore::Page TakeStore::list_page(std::size_t offset, std::size_t limit) const {
    std::lock_guard lock(mutex_);
    const std::vector<TakeEntry>& all = cached();
    Page page;
    page.total = all.size();
    const std::size_t begin = std::min(offset, all.size());
    const std::size_t end = begin + std::min(limit, all.size() - begin);
    page.takes.assign(all.begin() + static_cast<std::ptrdiff_t>(begin), all.begin() + static_cast<std::ptrdiff_t>(end));
    return page;
}

std::uint64_t TakeStore::sidecars_read() const {
    std::lock_guard lock(mutex_);
    return sidecars_read_;
}

std::optional<TakeEntry> TakeStore::find(std::string_view name) const {
    if (!valid_take_name(name)) return std::nullopt;
    std::lock_guard lock(mutex_);
    return load(std::string(name));
}

TakeStore::Removal TakeStore::remove(std::string_view name, std::string* error) {
    if (!valid_take_name(name)) return Removal::kNotFound;
    std::lock_guard lock(mutex_);
    if (name == recording_) {
        *error = "take '" + std::string(name) + "' is being recorded; stop it first";
        return Removal::kRecording;
    }
    cache_valid_ = false;
    const std::string d = dir(name);
    const std::string hidden = root_ + "/.deleting-" + std::string(name) + "-" + std::to_string(++trash_);
    if (::rename(d.c_str(), hidden.c_str()) != 0) {
        const int err = errno;
        if (err == ENOENT) return Removal::kNotFound;
        *error = "cannot delete " + d + ": " + errno_text(err);
        return Removal::kFailed;
    }
    std::error_code ec;
    fs::remove_all(hidden, ec);
    // Gone from every listing already; what could not be removed is only disk space.
    if (ec) spdlog::warn("takes: deleted {}, but removing {} failed: {}", name, hidden, ec.message());
    return Removal::kRemoved;
}

void TakeStore::mark_recording(std::string name) {
    std::lock_guard lock(mutex_);
    recording_ = std::move(name);
}

}  // namespace mocap::serve
