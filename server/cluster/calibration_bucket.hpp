// calibration_bucket.hpp — shared calibration: every subject's calibration in the JetStream
// key-value bucket mocap_calibration, so a calibration made on one host is used by any host
// that serves the subject (docs/cluster.md, "Shared calibration").
//
//   bucket    mocap_calibration: file storage, [cluster] raw_replicas copies, the last
//             kCalibrationHistory values of each key
//   key       <site>.<subject id>
//   value     JSON, {"format": "mocap-calibration", "version": 1, "site", "subject",
//             "host_id", "time_us", "calibration", "hmac_sha256"}; "calibration" is the text
//             form of skeleton/calibration.hpp (what a calibration file holds), checked against
//             the body model like a file; "hmac_sha256" signs the rest with the site's
//             calibration key (calibration_trust.hpp), present when the host has one
//   conflicts last writer wins: the value with the highest KV revision is the subject's
//             calibration on every host (two hosts that calibrate one subject at once both
//             end with the later write)
//
// A CalibrationStore wrapping the host's own store (the calibration files), which stays the
// fallback: load() reads only the local store, so a start never waits for NATS, and a
// calibration made while the bucket is unreachable is used here at once, saved locally and
// put to the bucket when it is reachable again (then it is the newest write). Calibrations
// from the bucket are also saved locally, so a host that restarts without the cluster starts
// from the newest one it knew.
//
// Who may write a calibration (docs/cluster.md): anyone the NATS server lets publish to
// $KV.mocap_calibration.>. So a value is used only if it is for a subject this host serves
// (ClusterConfig::subject_ids: no other key touches the solver, the counters per subject or
// the calibration directory), names this site and its key's subject, is newer (time_us) than
// the last one taken for the subject from the same host (a replay is not), is plausible (calibration_trust.hpp) and is
// authenticated: signed with the site's key when calibration_key_file is set; without a key,
// only a cluster with credentials is trusted (its server decides who may publish), and an
// anonymous one shares nothing inbound. Every refusal is counted and logged (once per reason,
// then at every tenfold count).
//
// Nothing here runs on a real-time thread: save() and serving() (the solver's assembler
// thread) queue work under a mutex held for a copy; one thread of this store does the NATS I/O
// and the local file writes. It owns its own NATS connection (credentials and TLS as the
// cluster publisher's). It watches <site>.* (the watch delivers every key's current value,
// then every change) and reads a subject's key when the subject's first frame arrives; a value
// with a revision newer than the one known for the subject is offered to the solver
// (PoseSolver::offer_calibration), except while a local calibration of that subject waits to
// be put (that one will be the newer write).
//
// Counters, component "calibration_kv": puts (values written), gets (keys read), received
// (newer calibrations from the bucket offered to the solver), errors (failed connects, bucket
// opens, puts, gets and watches, and values that do not parse), refused (values distrusted as
// above: nothing of them is applied or saved), permission_errors (publishes
// and subscriptions the server refused the [cluster] user: named in the log as such).
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "cluster/calibration_trust.hpp"
#include "cluster/cluster_config.hpp"
#include "cluster/nats_errors.hpp"
#include "core/counters.hpp"
#include "skeleton/calibration_store.hpp"

struct __natsConnection;  // NOLINT(bugprone-reserved-identifier): libnats names its types so
struct __jsCtx;           // NOLINT(bugprone-reserved-identifier): libnats names its types so
struct __kvStore;         // NOLINT(bugprone-reserved-identifier): libnats names its types so
struct __kvWatcher;       // NOLINT(bugprone-reserved-identifier): libnats names its types so
struct __kvEntry;         // NOLINT(bugprone-reserved-identifier): libnats names its types so

namespace mocap::cluster {

inline constexpr const char* kCalibrationBucket = "mocap_calibration";
inline constexpr int kCalibrationHistory = 5;
inline constexpr int kCalibrationFormatVersion = 1;

/// "<site>.<subject>".
std::string calibration_key(const std::string& site, std::uint32_t subject_id);
/// The bucket's value for a calibration made on host_id at time_us, signed with `key`
/// unless it is empty.
std::string calibration_value(const ClusterConfig& config, std::uint32_t subject_id,
                              const std::string& calibration_text, std::int64_t time_us, const std::string& key = {});
/// What a value says, or an error.
struct CalibrationValue {
    SignedFields fields;
    std::string signature;  ///< "" unsigned
    std::string error;      ///< non-empty: not a calibration value this version reads
};
CalibrationValue parse_calibration_value(const std::string& value);

class CalibrationBucket final : public skeleton::CalibrationStore {
public:
    /// local: the host's own store (nullptr = none). Nothing connects before bind().
    CalibrationBucket(ClusterConfig config, std::unique_ptr<skeleton::CalibrationStore> local);
    ~CalibrationBucket() override;
    CalibrationBucket(const CalibrationBucket&) = delete;
    CalibrationBucket& operator=(const CalibrationBucket&) = delete;

    /// The local store's calibration: a start never waits for the cluster.
    skeleton::StoredCalibration load(const skeleton::BodyModel& model, std::uint32_t subject_id) override;
    /// Queues the local save and the put; returns at once (errors are logged by this store).
    std::string save(const skeleton::BodyModel& model, std::uint32_t subject_id,
                     const skeleton::Calibration& calibration) override;
    /// Starts the store's thread: connects, opens (or creates) the bucket, watches it.
    void bind(const skeleton::BodyModel& model, skeleton::OfferFn offer) override;
    /// Queues a read of the subject's key.
    void serving(std::uint32_t subject_id) override;
    void register_metrics(MetricsRegistry& registry) const override;

private:
    static void on_reconnected(__natsConnection* nc, void* self);
    static void on_closed(__natsConnection* nc, void* self);
    void run();
    /// Store thread: a connection (retrying in the background); false if the options are bad.
    bool connect();
    void open_bucket();
    void close_bucket();
    void do_work();
    void put(std::uint32_t subject_id, const skeleton::Calibration& calibration);
    void get(std::uint32_t subject_id);
    /// A value from the bucket (watch or get): offered to the solver when it is newer.
    void consider(__kvEntry* entry);
    void note_error(const std::string& what);
    /// A value refused (counted; the first of each reason logged, then every tenfold count).
    void refuse(const std::string& reason, const std::string& detail);
    /// "" when the value may be used, else the reason it is refused.
    std::string distrust(std::uint32_t subject_id, const CalibrationValue& value);
    /// Why a request failed: the server's permission violation when it reported one (a
    /// refused publish only times out), else the status text.
    std::string failure_text(int status);

    ClusterConfig config_;
    std::unique_ptr<skeleton::CalibrationStore> local_;
    std::string key_prefix_;  // "<site>."
    skeleton::BodyModel model_;
    skeleton::OfferFn offer_;

    std::mutex mutex_;
    std::condition_variable wake_;
    bool stopping_ = false;                                        // guarded by mutex_
    bool closed_ = false;                                          // guarded by mutex_
    std::map<std::uint32_t, skeleton::Calibration> local_saves_;   // guarded: to save locally
    std::map<std::uint32_t, skeleton::Calibration> pending_puts_;  // guarded: not yet in the bucket
    std::vector<std::uint32_t> pending_gets_;                      // guarded by mutex_
    std::map<std::uint32_t, std::uint64_t> saves_;                 // guarded: save() calls per subject
    std::atomic<bool> reconnected_{false};

    // Store thread only.
    __natsOptions* options_ = nullptr;
    __natsConnection* connection_ = nullptr;
    __jsCtx* js_ = nullptr;
    __kvStore* kv_ = nullptr;
    __kvWatcher* watcher_ = nullptr;
    std::map<std::uint32_t, std::uint64_t> revision_;  // newest revision known per served subject
    /// Per served subject, the newest time_us taken from each host (a replay is not newer);
    /// at most kHostsPerSubject hosts each, the oldest forgotten first.
    static constexpr std::size_t kHostsPerSubject = 32;
    std::map<std::uint32_t, std::map<std::string, std::int64_t>> taken_us_;
    void note_taken(std::uint32_t subject_id, const std::string& host_id, std::int64_t time_us);
    std::map<std::string, std::uint64_t> refusals_;  // per reason
    std::string key_;                                // the site's calibration key ("" none)
    std::string key_error_;                          // the key file is set but unusable: nothing inbound is taken
    std::int64_t next_open_us_ = 0;
    std::int64_t next_put_us_ = 0;  // puts wait until then after a permission refusal
    std::string last_problem_;      // logged once until it changes or the bucket opens
    std::thread thread_;

    NatsErrors nats_errors_{std::string("calibration bucket ") + kCalibrationBucket};
    Counter puts_, gets_, received_, errors_, refused_;
    CounterGroup group_{"calibration_kv"};
};

}  // namespace mocap::cluster
