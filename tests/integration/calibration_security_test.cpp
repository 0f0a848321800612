// Who may write a calibration (docs/cluster.md, "Who may write a calibration"), against a real
// nats-server with JetStream that lets anyone in (no users): the lab-bench cluster of
// `allow_anonymous = true`. The host is told the site's calibration key (calibration_key_file)
// and serves subjects 1..4. Anyone can put a well-formed value into the bucket; only a value
// signed with the key, for a subject the host serves, and plausible (the body upright in the
// pose it was taken in) and newer than the last taken from its host is taken. Everything else
// (a replayed value too) is refused and counted, never applied, and nothing of it reaches the
// calibration directory.
#include <gtest/gtest.h>
#include <nats/nats.h>
#include <sys/stat.h>

#include <chrono>
#include <filesystem>

#include "cluster/calibration_bucket.hpp"
#include "harness.hpp"
#include "nats_harness.hpp"

namespace mocap::itest {
namespace {

using namespace std::chrono_literals;

constexpr const char* kSite = "bench";
constexpr const char* kKey = "site-key-0123456789abcdef0123456789abcdef";
constexpr const char* kOtherKey = "not-the-site-key-0123456789abcdef0123456789";

/// A calibration file's text for the default body model: the pelvis calibrated, the world
/// turned from the earth by q_world_earth ("1, 0, 0, 0": upright; "0, 1, 0, 0": upside down).
std::string calibration_text(const std::string& q_world_earth) {
    return "format = \"mocapd-calibration\"\nversion = 1\npose = \"t-pose\"\nheading = \"earth\"\n"
           "facing_heading_rad = 0.0\nq_world_earth = [" +
           q_world_earth + "]\n[q_sensor_segment]\npelvis = [1.0, 0.0, 0.0, 0.0]\n";
}

std::int64_t unix_us() {
    return std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::system_clock::now().time_since_epoch())
        .count();
}

/// A client of the bucket with no credentials: what anyone on the network can do.
class AnonymousBucket {
public:
    explicit AnonymousBucket(std::uint16_t port) {
        const std::string url = "nats://127.0.0.1:" + std::to_string(port);
        EXPECT_EQ(natsConnection_ConnectTo(&nc_, url.c_str()), NATS_OK);
        EXPECT_EQ(natsConnection_JetStream(&js_, nc_, nullptr), NATS_OK);
        EXPECT_EQ(js_KeyValue(&kv_, js_, cluster::kCalibrationBucket), NATS_OK);
    }
    ~AnonymousBucket() {
        if (kv_) kvStore_Destroy(kv_);
        if (js_) jsCtx_Destroy(js_);
        if (nc_) natsConnection_Destroy(nc_);
    }
    AnonymousBucket(const AnonymousBucket&) = delete;
    AnonymousBucket& operator=(const AnonymousBucket&) = delete;

    /// Puts a value for `subject` as host `host_id` made it, signed with `key` ("" unsigned);
    /// returns it.
    std::string put(std::uint32_t subject, const std::string& text, const std::string& key,
                    const std::string& host_id = "host-a") {
        cluster::ClusterConfig c;
        c.site = kSite;
        c.host_id = host_id;
        const std::string value = cluster::calibration_value(c, subject, text, unix_us(), key);
        put_value(subject, value);
        return value;
    }
    /// Puts `value` as it is (a value seen before, put again).
    void put_value(std::uint32_t subject, const std::string& value) {
        const std::string k = cluster::calibration_key(kSite, subject);
        EXPECT_EQ(kvStore_Put(nullptr, kv_, k.c_str(), value.data(), static_cast<int>(value.size())), NATS_OK) << k;
    }

private:
    natsConnection* nc_ = nullptr;
    jsCtx* js_ = nullptr;
    kvStore* kv_ = nullptr;
};

class CalibrationTrust : public OneHostClusterTest {
protected:
    void SetUp() override {
        OneHostClusterTest::SetUp();
        if (IsSkipped()) return;
        nats_ = std::make_unique<Process>(
            std::vector<std::string>{nats_server_bin(), "-a", "127.0.0.1", "-p", std::to_string(nats_port_), "-js",
                                     "-sd", dir_.file("js")},
            dir_.file("nats.log"));
        ASSERT_TRUE(wait_for_port(nats_port_, 15s)) << nats_->log();
        key_file_ = dir_.file("calibration.key");
        write_file(key_file_, std::string(kKey) + "\n");
        ::chmod(key_file_.c_str(), 0600);
        calibrations_ = dir_.file("calibrations");
        std::filesystem::create_directories(calibrations_);
        HostConfig h{.sink_port = sink_port_, .pose_port = pose_port_, .calibration_dir = calibrations_};
        h.skeleton = "auto_calibrate = \"off\"\n";
        h.cluster = cluster_section(nats_port_, kSite, "host-b",
                                    "allow_anonymous = true\ncalibration_key_file = \"" + key_file_ + "\"\n");
        daemon_ = start_mocapd(MOCAPD_BIN, h, dir_);
        ASSERT_FALSE(HasFailure());
        ASSERT_TRUE(wait_until(
            [&] {
                return daemon_->log().find("calibrations shared through the JetStream bucket") != std::string::npos;
            },
            30s))
            << "the host opens the bucket";
        bucket_ = std::make_unique<AnonymousBucket>(nats_port_);
    }

    void TearDown() override {
        bucket_.reset();
        OneHostClusterTest::TearDown();
    }

    /// Calibration files in the host's calibration directory.
    std::size_t calibration_files() const {
        std::size_t n = 0;
        for (const auto& e : std::filesystem::directory_iterator(calibrations_))
            n += e.path().filename().string().rfind("calibration-subject-", 0) == 0 ? 1 : 0;
        return n;
    }

    std::string key_file_, calibrations_;
    std::unique_ptr<AnonymousBucket> bucket_;
};

TEST_F(CalibrationTrust, AnonymousPoisoningIsRefusedCountedAndNeverSavedWhileASignedCalibrationIsTaken) {
    EXPECT_NE(daemon_->log().find("for a lab bench only"), std::string::npos) << "the anonymous cluster is named";
    // Subject 1: well-formed, upright, "made on host-a", not signed.
    bucket_->put(1, calibration_text("1.0, 0.0, 0.0, 0.0"), "");
    // Subject 2: signed with a key that is not the site's.
    bucket_->put(2, calibration_text("1.0, 0.0, 0.0, 0.0"), kOtherKey);
    // Subject 3: signed with the site's key, but the body upside down.
    bucket_->put(3, calibration_text("0.0, 1.0, 0.0, 0.0"), kKey);
    EXPECT_EQ(wait_stats_counter(
                  pose_port_, "calibration_kv.refused", [](auto v) { return v >= 3; }, 30s),
              3u);
    // Subject 4: signed with the site's key, upright: the one value taken.
    const std::string taken = bucket_->put(4, calibration_text("1.0, 0.0, 0.0, 0.0"), kKey);
    EXPECT_EQ(wait_stats_counter(
                  pose_port_, "calibration_kv.received", [](auto v) { return v >= 1; }, 30s),
              1u);
    EXPECT_TRUE(wait_until([&] { return std::filesystem::exists(calibrations_ + "/calibration-subject-4.toml"); }, 10s))
        << "the signed calibration is kept as the host's fallback";
    // The same signed value put again (a newer revision, an old time_us): a replay.
    bucket_->put_value(4, taken);
    EXPECT_EQ(wait_stats_counter(
                  pose_port_, "calibration_kv.refused", [](auto v) { return v >= 4; }, 30s),
              4u);
    EXPECT_EQ(stats_counter(pose_port_, "calibration_kv.received"), 1u);
    EXPECT_EQ(calibration_files(), 1u) << "nothing of the refused values reaches the calibration directory";
    const std::string log = daemon_->log();
    EXPECT_NE(log.find("an unsigned value (calibration_key_file is set)"), std::string::npos) << log;
    EXPECT_NE(log.find("a signature that does not verify"), std::string::npos) << log;
    EXPECT_NE(log.find("the body would not stand upright"), std::string::npos) << log;
    EXPECT_NE(log.find("(a replay)"), std::string::npos) << log;
}

TEST_F(CalibrationTrust, TwoThousandKeysForSubjectsNobodyConfiguredCreateNoFile) {
    // Signed with the site's key and upright: only the subject bound refuses them.
    constexpr std::uint32_t kKeys = 2000;
    for (std::uint32_t i = 0; i < kKeys; ++i)
        bucket_->put(100 + i, calibration_text("1.0, 0.0, 0.0, 0.0"), kKey);
    EXPECT_EQ(wait_stats_counter(
                  pose_port_, "calibration_kv.refused", [](auto v) { return v >= kKeys; }, 120s),
              kKeys);
    EXPECT_EQ(stats_counter(pose_port_, "calibration_kv.received"), 0u);
    EXPECT_EQ(calibration_files(), 0u);
    EXPECT_LE(count_lines(daemon_->log(), "a subject this host does not serve"), 4u)
        << "logged at the 1st, 10th, 100th and 1000th, not 2000 times";
}

}  // namespace
}  // namespace mocap::itest
