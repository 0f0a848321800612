#include "cluster/calibration_bucket.hpp"

#include <nats/nats.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <charconv>
#include <chrono>
#include <nlohmann/json.hpp>

namespace mocap::cluster {
namespace {

constexpr const char* kFormat = "mocap-calibration";
/// A bucket that cannot be opened is tried again this often.
constexpr std::int64_t kOpenRetryUs = 1'000'000;
/// A connection the client closed for good (refused credentials) is opened again this often.
constexpr std::int64_t kReconnectUs = 2'000'000;
/// JetStream API requests (bucket lookup and creation, put, get) wait this long for the server.
constexpr std::int64_t kApiWaitMs = 2000;
/// Puts the server's permissions refused are tried again this often (each try is a refusal
/// in the server's log).
constexpr std::int64_t kRefusedPutRetryUs = 30'000'000;
constexpr const char* kRefusedPrefix = "the NATS server refused it: ";
/// The store thread looks at its queue at least this often while it waits for the watch.
constexpr std::int64_t kWatchWaitMs = 100;

/// Text from a value, for the log: anyone may have written it, so at most 64 characters and
/// no control character (a '?' instead).
std::string loggable(const std::string& text) {
    constexpr std::size_t kMax = 64;
    std::string out = text.substr(0, kMax);
    for (char& ch : out) {
        if (static_cast<unsigned char>(ch) < 0x20 || ch == 0x7f) ch = '?';
    }
    return text.size() > kMax ? out + "..." : out;
}

std::int64_t steady_us() {
    return std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::steady_clock::now().time_since_epoch())
        .count();
}

std::int64_t unix_us() {
    return std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::system_clock::now().time_since_epoch())
        .count();
}

}  // namespace

std::string calibration_key(const std::string& site, std::uint32_t subject_id) {
    return site + "." + std::to_string(subject_id);
}

std::string calibration_value(const ClusterConfig& config, std::uint32_t subject_id,
                              const std::string& calibration_text, std::int64_t time_us, const std::string& key) {
    nlohmann::ordered_json v{{"format", kFormat},
                             {"version", kCalibrationFormatVersion},
                             {"site", config.site},
                             {"subject", subject_id},
                             {"host_id", config.host_id},
                             {"time_us", time_us},
                             {"calibration", calibration_text}};
    if (!key.empty())
        v["hmac_sha256"] =
            calibration_signature(key, {config.site, subject_id, config.host_id, time_us, calibration_text});
    return v.dump();
}

CalibrationValue parse_calibration_value(const std::string& value) {
    CalibrationValue out;
    const auto v = nlohmann::json::parse(value, nullptr, false);
    if (v.is_discarded() || !v.is_object()) {
        out.error = "not JSON";
        return out;
    }
    if (v.value("format", "") != kFormat) {
        out.error = std::string("format is not \"") + kFormat + "\"";
        return out;
    }
    if (!v.contains("version") || !v["version"].is_number_integer() ||
        v["version"].get<int>() != kCalibrationFormatVersion) {
        out.error = "version " + (v.contains("version") ? v["version"].dump() : std::string("missing")) +
                    ", this host reads version " + std::to_string(kCalibrationFormatVersion);
        return out;
    }
    if (!v.contains("calibration") || !v["calibration"].is_string()) {
        out.error = "no calibration text";
        return out;
    }
    const auto text = [&](const char* name) {
        return v.contains(name) && v[name].is_string() ? v[name].get<std::string>() : std::string();
    };
    out.fields.calibration_text = v["calibration"].get<std::string>();
    out.fields.site = text("site");
    out.fields.host_id = text("host_id");
    out.signature = text("hmac_sha256");
    if (v.contains("subject") && v["subject"].is_number_unsigned() && v["subject"].get<std::uint64_t>() <= UINT32_MAX)
        out.fields.subject = static_cast<std::uint32_t>(v["subject"].get<std::uint64_t>());
    if (v.contains("time_us") && v["time_us"].is_number_integer())
        out.fields.time_us = v["time_us"].get<std::int64_t>();
    return out;
}

CalibrationBucket::CalibrationBucket(ClusterConfig config, std::unique_ptr<skeleton::CalibrationStore> local)
    : config_(std::move(config)), local_(std::move(local)), key_prefix_(config_.site + ".") {
    std::sort(config_.subject_ids.begin(), config_.subject_ids.end());
    if (!config_.calibration_key_file.empty()) {
        if (auto key = read_calibration_key(config_.calibration_key_file, &key_error_)) key_ = std::move(*key);
    }
    group_.add("puts", puts_);
    group_.add("gets", gets_);
    group_.add("received", received_);
    group_.add("errors", errors_);
    group_.add("refused", refused_);
    group_.add("permission_errors", nats_errors_.permission_errors());
}

CalibrationBucket::~CalibrationBucket() {
    {
        std::lock_guard lock(mutex_);
        stopping_ = true;
    }
    wake_.notify_all();
    if (thread_.joinable()) thread_.join();
    close_bucket();
    if (js_) {
        jsCtx_Destroy(js_);
        js_ = nullptr;
    }
    if (connection_) {
        {
            std::lock_guard lock(mutex_);
            closed_ = false;
        }
        natsConnection_Close(connection_);
        // The client runs the closed callback on its own thread, after Close returns: wait for
        // it before `this` may go away.
        std::unique_lock lock(mutex_);
        if (!wake_.wait_for(lock, std::chrono::seconds(5), [this] { return closed_; }))
            spdlog::warn("cluster: calibration bucket: the NATS client did not confirm its close within 5 s");
        lock.unlock();
        natsConnection_Destroy(connection_);
        connection_ = nullptr;
    }
    if (options_) natsOptions_Destroy(options_);
}

skeleton::StoredCalibration CalibrationBucket::load(const skeleton::BodyModel& model, std::uint32_t subject_id) {
    if (!local_) return {};
    return local_->load(model, subject_id);
}

std::string CalibrationBucket::save(const skeleton::BodyModel& /*model*/, std::uint32_t subject_id,
                                    const skeleton::Calibration& calibration) {
    {
        std::lock_guard lock(mutex_);
        if (local_) local_saves_[subject_id] = calibration;
        pending_puts_[subject_id] = calibration;
        ++saves_[subject_id];
    }
    wake_.notify_all();
    return {};
}

void CalibrationBucket::bind(const skeleton::BodyModel& model, skeleton::OfferFn offer) {
    if (!key_error_.empty()) {
        spdlog::error("cluster: calibration_key_file {}; calibrations from the bucket are refused", key_error_);
    } else if (config_.anonymous()) {
        spdlog::warn(
            "cluster: connected without credentials (allow_anonymous): any client of the NATS server may publish "
            "to this site, which is for a lab bench only (docs/cluster.md); {}",
            key_.empty() ? "calibrations from the bucket are refused (set calibration_key_file to share them)"
                         : "calibrations from the bucket are taken only when signed with calibration_key_file");
    }
    model_ = model;
    offer_ = std::move(offer);
    thread_ = std::thread([this] { run(); });
}

void CalibrationBucket::serving(std::uint32_t subject_id) {
    {
        std::lock_guard lock(mutex_);
        pending_gets_.push_back(subject_id);
    }
    wake_.notify_all();
}

void CalibrationBucket::register_metrics(MetricsRegistry& registry) const {
    registry.add(group_);
}

void CalibrationBucket::on_reconnected(natsConnection* /*nc*/, void* self) {
    auto* b = static_cast<CalibrationBucket*>(self);
    b->reconnected_.store(true);
    b->wake_.notify_all();
}

void CalibrationBucket::on_closed(natsConnection* /*nc*/, void* self) {
    auto* b = static_cast<CalibrationBucket*>(self);
    {
        std::lock_guard lock(b->mutex_);
        b->closed_ = true;
    }
    b->wake_.notify_all();
}

void CalibrationBucket::note_error(const std::string& what) {
    errors_.add();
    if (what == last_problem_) return;  // a lasting problem is logged once
    last_problem_ = what;
    spdlog::warn("cluster: calibration bucket {}: {}", kCalibrationBucket, what);
}

std::string CalibrationBucket::failure_text(int status) {
    const std::string refused = nats_errors_.take_violation();
    if (refused.empty()) return nats_error_text(status);
    return kRefusedPrefix + refused + " (the [cluster] user needs publish permission on $JS.API.> and $KV." +
           kCalibrationBucket + ".>, config/nats/nats-server.conf)";
}

bool CalibrationBucket::connect() {
    if (!options_) {
        std::string error;
        if (!make_nats_options(config_, &options_, &error)) {
            note_error(error + "; calibrations stay local");
            return false;
        }
        (void)natsOptions_SetMaxReconnect(options_, -1);
        (void)natsOptions_SetReconnectWait(options_, config_.reconnect_wait_ms);
        (void)natsOptions_SetReconnectedCB(options_, &CalibrationBucket::on_reconnected, this);
        (void)natsOptions_SetClosedCB(options_, &CalibrationBucket::on_closed, this);
        nats_errors_.install(options_);
    }
    // The first attempt without the retry, so that its reason reaches the log.
    (void)natsOptions_SetRetryOnFailedConnect(options_, false, nullptr, nullptr);
    natsStatus s = natsConnection_Connect(&connection_, options_);
    if (s == NATS_OK) return true;
    note_error("cannot connect to " + config_.nats_url + ": " + nats_error_text(s) +
               "; calibrations stay local until it is reachable");
    connection_ = nullptr;
    (void)natsOptions_SetRetryOnFailedConnect(options_, true, &CalibrationBucket::on_reconnected, this);
    s = natsConnection_Connect(&connection_, options_);
    if (s == NATS_OK || s == NATS_NOT_YET_CONNECTED) return true;
    connection_ = nullptr;
    return false;
}

void CalibrationBucket::open_bucket() {
    next_open_us_ = steady_us() + kOpenRetryUs;
    if (!js_) {
        jsOptions o;
        jsOptions_Init(&o);
        o.Wait = kApiWaitMs;
        if (const natsStatus s = natsConnection_JetStream(&js_, connection_, &o); s != NATS_OK) {
            js_ = nullptr;
            note_error("no JetStream context: " + nats_error_text(s));
            return;
        }
    }
    kvStore* kv = nullptr;
    natsStatus s = js_KeyValue(&kv, js_, kCalibrationBucket);
    if (s == NATS_NOT_FOUND) {
        kvConfig c;
        kvConfig_Init(&c);
        c.Bucket = kCalibrationBucket;
        c.Description = "mocapd: the calibration of each subject, key <site>.<subject id>";
        c.History = kCalibrationHistory;
        c.StorageType = js_FileStorage;
        c.Replicas = static_cast<int>(config_.raw_replicas);
        s = js_CreateKeyValue(&kv, js_, &c);
    }
    if (s != NATS_OK) {
        const bool no_js = s == NATS_NO_RESPONDERS;
        note_error("cannot open it on " + config_.nats_url + ": " + failure_text(s) +
                   (no_js ? " (JetStream is not enabled on the server)" : "") +
                   "; calibrations stay local until it opens");
        return;
    }
    kv_ = kv;
    kvWatchOptions wo;
    kvWatchOptions_Init(&wo);
    wo.IgnoreDeletes = true;
    const std::string keys = key_prefix_ + "*";
    if (s = kvStore_Watch(&watcher_, kv_, keys.c_str(), &wo); s != NATS_OK) {
        watcher_ = nullptr;
        note_error("cannot watch " + keys + ": " + failure_text(s));
        close_bucket();
        return;
    }
    last_problem_.clear();
    spdlog::info("cluster: calibrations shared through the JetStream bucket {} (keys {}<subject>)", kCalibrationBucket,
                 key_prefix_);
}

void CalibrationBucket::close_bucket() {
    if (watcher_) {
        (void)kvWatcher_Stop(watcher_);
        kvWatcher_Destroy(watcher_);
        watcher_ = nullptr;
    }
    if (kv_) {
        kvStore_Destroy(kv_);
        kv_ = nullptr;
    }
}

void CalibrationBucket::run() {
    std::int64_t next_connect_us = 0;
    std::unique_lock lock(mutex_);
    while (!stopping_) {
        const bool closed = std::exchange(closed_, false);
        lock.unlock();
        const std::int64_t now = steady_us();
        if (closed && connection_) {
            // The client gave up on this connection (it does after the same refusal twice):
            // open a new one later, as the cluster publisher does.
            close_bucket();
            if (js_) jsCtx_Destroy(js_);
            js_ = nullptr;
            natsConnection_Destroy(connection_);
            connection_ = nullptr;
            next_connect_us = now + kReconnectUs;
        }
        if (!connection_ && now >= next_connect_us && !connect()) next_connect_us = now + kReconnectUs;
        if (reconnected_.exchange(false)) {
            // A new server (or the same one restarted) may not have the watch's consumer:
            // watch afresh; the watch delivers every key again and old revisions are skipped.
            close_bucket();
            next_open_us_ = 0;
        }
        if (connection_ && !kv_ && natsConnection_Status(connection_) == NATS_CONN_STATUS_CONNECTED &&
            now >= next_open_us_)
            open_bucket();
        do_work();
        if (watcher_) {
            kvEntry* e = nullptr;
            const natsStatus s = kvWatcher_Next(&e, watcher_, kWatchWaitMs);
            if (s == NATS_OK && e != nullptr) {
                consider(e);
                kvEntry_Destroy(e);
            } else if (s != NATS_OK && s != NATS_TIMEOUT) {
                note_error("watch stopped: " + nats_error_text(s) + "; watching again");
                close_bucket();
            }
        }
        lock.lock();
        if (!watcher_) {
            wake_.wait_for(lock, std::chrono::milliseconds(250), [this] {
                return stopping_ || closed_ || !pending_gets_.empty() || !local_saves_.empty() || reconnected_.load();
            });
        }
    }
}

void CalibrationBucket::do_work() {
    std::map<std::uint32_t, skeleton::Calibration> saves, puts;
    std::vector<std::uint32_t> gets;
    {
        std::lock_guard lock(mutex_);
        saves.swap(local_saves_);
        gets.swap(pending_gets_);
        if (kv_ && steady_us() >= next_put_us_) puts.swap(pending_puts_);
    }
    for (const auto& [id, calibration] : saves) {
        if (const std::string err = local_->save(model_, id, calibration); !err.empty())
            spdlog::error("subject {}: {}", id, err);
    }
    for (const auto& [id, calibration] : puts)
        put(id, calibration);
    if (!kv_) return;  // the watch delivers every key once the bucket opens
    for (const std::uint32_t id : gets)
        get(id);
}

void CalibrationBucket::put(std::uint32_t subject_id, const skeleton::Calibration& calibration) {
    const std::string key = calibration_key(config_.site, subject_id);
    const std::int64_t now_us = unix_us();
    const std::string value =
        calibration_value(config_, subject_id, skeleton::serialize_calibration(model_, calibration), now_us, key_);
    std::uint64_t rev = 0;
    const natsStatus s = kvStore_Put(&rev, kv_, key.c_str(), value.data(), static_cast<int>(value.size()));
    if (s != NATS_OK) {
        const std::string why = failure_text(s);
        // A refusal lasts until the server's config changes: asked again every 30 s, not at once.
        const bool refused = why.rfind(kRefusedPrefix, 0) == 0;
        if (refused) next_put_us_ = steady_us() + kRefusedPutRetryUs;
        note_error("cannot put " + key + ": " + why + "; put again " +
                   (refused ? std::string("in 30 s") : std::string("when the bucket answers")));
        std::lock_guard lock(mutex_);
        pending_puts_.emplace(subject_id, calibration);  // unless a newer one came meanwhile
        return;
    }
    puts_.add();
    // Our own write comes back through the watch: not a newer calibration.
    revision_[subject_id] = std::max(revision_[subject_id], rev);
    note_taken(subject_id, config_.host_id, now_us);
    spdlog::info("subject {}: calibration shared in bucket {} (key {}, revision {})", subject_id, kCalibrationBucket,
                 key, rev);
}

void CalibrationBucket::get(std::uint32_t subject_id) {
    const std::string key = calibration_key(config_.site, subject_id);
    kvEntry* e = nullptr;
    const natsStatus s = kvStore_Get(&e, kv_, key.c_str());
    if (s == NATS_NOT_FOUND) {
        gets_.add();
        return;
    }
    if (s != NATS_OK) {
        note_error("cannot get " + key + ": " + failure_text(s));
        return;
    }
    gets_.add();
    consider(e);
    kvEntry_Destroy(e);
}

void CalibrationBucket::consider(kvEntry* entry) {
    if (kvEntry_Operation(entry) != kvOp_Put) return;
    const std::string key = kvEntry_Key(entry);
    if (key.rfind(key_prefix_, 0) != 0) return;
    std::uint32_t id = 0;
    const char* first = key.data() + key_prefix_.size();
    const char* last = key.data() + key.size();
    if (const auto r = std::from_chars(first, last, id); r.ec != std::errc() || r.ptr != last || id == 0) {
        refuse("a key that names no subject", key);
        return;
    }
    if (!std::binary_search(config_.subject_ids.begin(), config_.subject_ids.end(), id)) {
        refuse("a subject this host does not serve", key);
        return;
    }
    const std::uint64_t rev = kvEntry_Revision(entry);
    if (rev <= revision_[id]) return;  // known already (our own put, or the watch and a get both)
    revision_[id] = rev;
    const std::string value(static_cast<const char*>(kvEntry_Value(entry)),
                            static_cast<std::size_t>(kvEntry_ValueLen(entry)));
    const CalibrationValue v = parse_calibration_value(value);
    const std::string made_on = loggable(v.fields.host_id);
    const std::string where = "bucket " + std::string(kCalibrationBucket) + " (key " + key + ", revision " +
                              std::to_string(rev) + (made_on.empty() ? "" : ", made on " + made_on) + ")";
    if (!v.error.empty()) {
        note_error("ignoring " + where + ": " + v.error);
        return;
    }
    if (const std::string why = distrust(id, v); !why.empty()) {
        refuse(why, where);
        return;
    }
    auto parsed = skeleton::parse_calibration(model_, v.fields.calibration_text);
    if (!parsed.calibration) {
        note_error("ignoring " + where + ": " + parsed.error);
        return;
    }
    if (const std::string why = implausible_calibration(*parsed.calibration); !why.empty()) {
        refuse("an implausible calibration", where + ": " + why);
        return;
    }
    std::uint64_t saves_seen = 0;
    {
        std::lock_guard lock(mutex_);
        // A local calibration of this subject waits to be put: it will be the newer write.
        if (pending_puts_.count(id) != 0) return;
        saves_seen = saves_[id];
    }
    note_taken(id, v.fields.host_id, v.fields.time_us);
    if (local_) {
        if (const std::string err = local_->save(model_, id, *parsed.calibration); !err.empty())
            spdlog::error("subject {}: {}", id, err);
    }
    received_.add();
    offer_(id, *parsed.calibration, where, saves_seen);
}

std::string CalibrationBucket::distrust(std::uint32_t subject_id, const CalibrationValue& v) {
    if (v.fields.site != config_.site || v.fields.subject != subject_id)
        return "a value whose site or subject is not its key's";
    if (!key_error_.empty()) return "unusable calibration_key_file";
    if (!key_.empty()) {
        if (v.signature.empty()) return "an unsigned value (calibration_key_file is set)";
        if (!signature_matches(key_, v.fields, v.signature))
            return "a signature that does not verify with calibration_key_file";
    } else if (config_.anonymous()) {
        return "an unsigned value on an anonymous cluster (set calibration_key_file to share calibrations)";
    }
    if (const auto s = taken_us_.find(subject_id); s != taken_us_.end()) {
        if (const auto h = s->second.find(v.fields.host_id); h != s->second.end() && v.fields.time_us <= h->second)
            return "a value not newer than one taken before from its host (a replay)";
    }
    return {};
}

void CalibrationBucket::note_taken(std::uint32_t subject_id, const std::string& host_id, std::int64_t time_us) {
    auto& hosts = taken_us_[subject_id];
    auto& t = hosts[host_id];
    t = std::max(t, time_us);
    if (hosts.size() <= kHostsPerSubject) return;
    hosts.erase(
        std::min_element(hosts.begin(), hosts.end(), [](const auto& a, const auto& b) { return a.second < b.second; }));
}

void CalibrationBucket::refuse(const std::string& reason, const std::string& detail) {
    refused_.add();
    const std::uint64_t n = ++refusals_[reason];
    std::uint64_t tenfold = 1;
    while (tenfold < n)
        tenfold *= 10;
    if (n != tenfold) return;  // the 1st, 10th, 100th ... of each reason
    spdlog::warn("cluster: calibration bucket {}: refused {} ({}; {} so far for this reason)", kCalibrationBucket,
                 detail, reason, n);
}

}  // namespace mocap::cluster
