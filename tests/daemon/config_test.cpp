#include "daemon/config.hpp"
#include "serve/serve_config.hpp"

#include <gtest/gtest.h>

namespace mocap::daemon {
namespace {

std::optional<DaemonConfig> parse(const std::string& text, std::string* err) {
    return parse_config(text, "test.toml", err);
}

TEST(Config, EmbeddedDefaultIsValidAndMatchesStructDefaults) {
    std::string err;
    const auto c = parse_config(embedded_default_config(), "mocapd.toml", &err);
    ASSERT_TRUE(c) << err;
    const DaemonConfig d;
    EXPECT_EQ(c->sink_listen.port, 7000);
    EXPECT_EQ(c->pose_listen.port, 7001);
    EXPECT_TRUE(c->control_loopback_only);
    EXPECT_EQ(c->serve_threads, d.serve_threads);
    EXPECT_EQ(c->bvh_threads, d.bvh_threads);
    EXPECT_EQ(c->http_threads, d.http_threads);
    EXPECT_EQ(c->calibration_dir, d.calibration_dir);
    EXPECT_EQ(c->heading_align, d.heading_align);
    EXPECT_EQ(c->log_level, d.log_level);
    EXPECT_EQ(c->ring_capacity, d.ring_capacity);
    EXPECT_EQ(c->subject_id_base, d.subject_id_base);
    EXPECT_EQ(d.subject_id_base, 0u);
    EXPECT_DOUBLE_EQ(c->keepalive_period_s, d.keepalive_period_s);
    EXPECT_EQ(c->max_clients, d.max_clients);
    EXPECT_EQ(c->client_queue_frames, d.client_queue_frames);
    EXPECT_DOUBLE_EQ(c->assembly_deadline_ms, d.assembly_deadline_ms);
    EXPECT_EQ(c->filter_name, d.filter_name);
    EXPECT_TRUE(c->segments.empty());
    EXPECT_TRUE(c->control_token.empty());
}

TEST(Config, EmptyFileGivesDefaults) {
    std::string err;
    const auto c = parse("", &err);
    ASSERT_TRUE(c) << err;
    EXPECT_EQ(c->pose_listen.str(), "0.0.0.0:7001");
}

TEST(Config, UnknownKeyNamesKeyAndLine) {
    std::string err;
    EXPECT_FALSE(parse("[serve]\nmax_clients = 10\nmax_clinets = 3\n", &err));
    EXPECT_EQ(err, "test.toml:3: serve.max_clinets: unknown key");
    EXPECT_FALSE(parse("[servr]\n", &err));
    EXPECT_EQ(err, "test.toml:1: servr: unknown key");
}

TEST(Config, WrongTypeAndRangeNameKeyAndLine) {
    std::string err;
    EXPECT_FALSE(parse("\n[pipeline]\nworkers = \"two\"\n", &err));
    EXPECT_EQ(err, "test.toml:3: pipeline.workers: expected an integer");
    EXPECT_FALSE(parse("[pipeline]\nring_capacity = 1000\n", &err));
    EXPECT_EQ(err, "test.toml:2: pipeline.ring_capacity: must be a power of two");
    EXPECT_FALSE(parse("[serve]\npose_listen = \"localhost\"\n", &err));
    EXPECT_EQ(err, "test.toml:2: serve.pose_listen: expected \"host:port\"");
    EXPECT_FALSE(parse("[serve]\npose_listen = \"h:70000\"\n", &err));
    EXPECT_EQ(err, "test.toml:2: serve.pose_listen: port must be 1..65535");
    EXPECT_FALSE(parse("[log]\nlevel = \"loud\"\n", &err));
    EXPECT_EQ(err, "test.toml:2: log.level: must be one of trace, debug, info, warn, error, off");
}

TEST(Config, HttpAllowedHostsAreHostNames) {
    std::string err;
    const auto c = parse("[http]\nallowed_hosts = [\"mocap.lab\", \"studio-1\"]\n", &err);
    ASSERT_TRUE(c) << err;
    EXPECT_EQ(c->http_allowed_hosts, (std::vector<std::string>{"mocap.lab", "studio-1"}));
    EXPECT_FALSE(parse("[http]\nallowed_hosts = [\"http://mocap.lab\"]\n", &err));
    EXPECT_EQ(err, "test.toml:2: http.allowed_hosts: expected host names like \"mocap.lab\" (no scheme, no port)");
    EXPECT_FALSE(parse("[http]\nallowed_hosts = [\"mocap.lab:8080\"]\n", &err));
    EXPECT_FALSE(parse("[http]\nallowed_hosts = [\"\"]\n", &err));
    EXPECT_FALSE(parse("[http]\nallowed_hosts = [3]\n", &err));
}

// An integer too large for a double to hold exactly used to escape parse_config as
// std::bad_optional_access (found by fuzz_config); it must be an ordinary range error.
TEST(Config, HugeIntegerForAFloatKeyIsARangeError) {
    std::string err;
    EXPECT_FALSE(parse("[skeleton]\nfacing_heading_deg = 99999999999999030\n", &err));
    EXPECT_EQ(err, "test.toml:2: skeleton.facing_heading_deg: must be between -360 and 360");
    EXPECT_FALSE(parse("[skeleton]\nfacing_sensor_axis = [9007199254740993, 0, 0]\n", &err));
    EXPECT_EQ(err, "test.toml:2: skeleton.facing_sensor_axis: components must be within +-1");
    const auto ok = parse("[skeleton]\nfacing_heading_deg = 90\n", &err);
    ASSERT_TRUE(ok) << err;
    EXPECT_EQ(ok->facing_heading_deg, 90.0);
}

TEST(Config, AutoCalibrateChoices) {
    std::string err;
    auto c = parse("[skeleton]\nauto_calibrate = \"off\"\n", &err);
    ASSERT_TRUE(c) << err;
    EXPECT_EQ(c->auto_calibrate, "off");
    EXPECT_FALSE(parse("[skeleton]\nauto_calibrate = \"always\"\n", &err));
    EXPECT_EQ(err, "test.toml:2: skeleton.auto_calibrate: must be \"t-pose\", \"n-pose\" or \"off\"");
}

TEST(Config, SyntaxErrorNamesLine) {
    std::string err;
    EXPECT_FALSE(parse("[log]\nlevel = \n", &err));
    EXPECT_NE(err.find("test.toml:2: syntax:"), std::string::npos) << err;
}

TEST(Config, SegmentsAndSocketCan) {
    std::string err;
    const auto c = parse(R"([[ingest.socketcan]]
interface = "vcan0"
subject = 3

[filter]
name = "madgwick"
params = { beta = 0.05, init = "fast" }

[[skeleton.segment]]
name = "pelvis"
node = 1

[[skeleton.segment]]
name = "thigh"
parent = "pelvis"
offset_m = [0.0, -0.1, -0.08]
node = 2
filter = "pf"
)",
                         &err);
    ASSERT_TRUE(c) << err;
    ASSERT_EQ(c->socketcan.size(), 1u);
    EXPECT_EQ(c->socketcan[0].interface, "vcan0");
    EXPECT_EQ(c->socketcan[0].subject, 3u);
    ASSERT_EQ(c->filter_params.size(), 2u);
    EXPECT_EQ(c->filter_params[0].first, "beta");
    EXPECT_EQ(c->filter_params[0].second, "0.050000000000000003");
    ASSERT_EQ(c->segments.size(), 2u);
    EXPECT_EQ(c->segments[1].parent, "pelvis");
    EXPECT_DOUBLE_EQ(c->segments[1].offset_m[2], -0.08);
    EXPECT_EQ(c->segments[1].filter, "pf");
}

TEST(Config, SegmentErrors) {
    std::string err;
    EXPECT_FALSE(
        parse("[[skeleton.segment]]\nname = \"a\"\nnode = 1\n[[skeleton.segment]]\n"
              "name = \"b\"\nparent = \"zz\"\nnode = 2\n",
              &err));
    EXPECT_EQ(err, "test.toml:6: skeleton.segment.parent: parent must be a segment listed earlier");
    EXPECT_FALSE(
        parse("[[skeleton.segment]]\nname = \"a\"\nnode = 1\n[[skeleton.segment]]\n"
              "name = \"b\"\nparent = \"a\"\nnode = 1\n",
              &err));
    EXPECT_EQ(err, "test.toml:7: skeleton.segment.node: node id used twice");
    EXPECT_FALSE(parse("[[skeleton.segment]]\nname = \"a\"\nnode = 99\n", &err));
    EXPECT_EQ(err, "test.toml:3: skeleton.segment.node: must be between 1 and 63");
}

}  // namespace
}  // namespace mocap::daemon

namespace mocap::daemon {
namespace {

TEST(ConfigOutputs, DefaultsAndValues) {
    std::string err;
    const auto d = parse_config(embedded_default_config(), "mocapd.toml", &err);
    ASSERT_TRUE(d) << err;
    const DaemonConfig s;
    EXPECT_EQ(d->bvh_listen.str(), "0.0.0.0:7002");
    EXPECT_EQ(d->bvh_live, s.bvh_live);
    EXPECT_EQ(d->bvh_subject, s.bvh_subject);
    EXPECT_DOUBLE_EQ(d->bvh_units_per_m, s.bvh_units_per_m);
    EXPECT_EQ(d->bvh_rotation_order, s.bvh_rotation_order);
    EXPECT_DOUBLE_EQ(d->bvh_frame_time_s, s.bvh_frame_time_s);
    EXPECT_EQ(d->record_dir, s.record_dir);
    EXPECT_EQ(d->raw_record, s.raw_record);
    EXPECT_DOUBLE_EQ(d->raw_rotate_mb, s.raw_rotate_mb);
    EXPECT_DOUBLE_EQ(d->raw_rotate_s, s.raw_rotate_s);
    EXPECT_EQ(d->raw_ring_capacity, s.raw_ring_capacity);
    EXPECT_DOUBLE_EQ(d->take_start_min_free_mb, s.take_start_min_free_mb);
    for (const char* bad : {"take_start_min_free_mb = -1\n", "take_start_min_free_mb = 0.001\n"})
        EXPECT_FALSE(parse_config(std::string("[outputs]\n") + bad, "t.toml", &err)) << bad;
    const auto off = parse_config("[outputs]\ntake_start_min_free_mb = 0\n", "t.toml", &err);
    ASSERT_TRUE(off) << err;
    EXPECT_DOUBLE_EQ(off->take_start_min_free_mb, 0.0);

    const auto c = parse_config(
        "[outputs]\nbvh_live = false\nbvh_listen = \"127.0.0.1:9002\"\nbvh_unit = \"m\"\n"
        "bvh_rotation_order = \"XYZ\"\nbvh_subject = 3\nraw_record = true\n"
        "raw_rotate_mb = 1.5\nrecord_dir = \"/tmp/x\"\n",
        "t.toml", &err);
    ASSERT_TRUE(c) << err;
    EXPECT_FALSE(c->bvh_live);
    EXPECT_EQ(c->bvh_listen.port, 9002);
    EXPECT_DOUBLE_EQ(c->bvh_units_per_m, 1.0);
    EXPECT_EQ(c->bvh_rotation_order, "XYZ");
    EXPECT_EQ(c->bvh_subject, 3u);
    EXPECT_TRUE(c->raw_record);
    EXPECT_DOUBLE_EQ(c->raw_rotate_mb, 1.5);
    EXPECT_EQ(c->record_dir, "/tmp/x");
}

TEST(ConfigOutputs, ErrorsNameKeyAndLine) {
    std::string err;
    EXPECT_FALSE(parse_config("[outputs]\nbvh_unit = \"inch\"\n", "t.toml", &err));
    EXPECT_EQ(err, "t.toml:2: outputs.bvh_unit: must be \"cm\", \"m\" or \"mm\"");
    EXPECT_FALSE(parse_config("[outputs]\n\nbvh_rotation_order = \"ZZY\"\n", "t.toml", &err));
    EXPECT_EQ(err, "t.toml:3: outputs.bvh_rotation_order: must be three distinct letters of XYZ, e.g. \"ZXY\"");
    EXPECT_FALSE(parse_config("[outputs]\nraw_ring_capacity = 1000\n", "t.toml", &err));
    EXPECT_EQ(err, "t.toml:2: outputs.raw_ring_capacity: must be a power of two");
    EXPECT_FALSE(parse_config("[outputs]\nraw_record = 1\n", "t.toml", &err));
    EXPECT_EQ(err, "t.toml:2: outputs.raw_record: expected true or false");
    EXPECT_FALSE(parse_config("[outputs]\nbvh_frame_time_s = -0.01\n", "t.toml", &err));
    EXPECT_NE(err.find("outputs.bvh_frame_time_s"), std::string::npos) << err;
}

}  // namespace
}  // namespace mocap::daemon

namespace mocap::daemon {
namespace {

TEST(ConfigServe, RateLimitKeysDefaultsMatchTheServeLayerAndRangesAreChecked) {
    std::string err;
    const auto d = parse_config(embedded_default_config(), "mocapd.toml", &err);
    ASSERT_TRUE(d) << err;
    const serve::ServeConfig s;
    EXPECT_DOUBLE_EQ(d->max_client_messages_per_s, s.max_client_messages_per_s);
    EXPECT_EQ(d->client_message_burst, s.client_message_burst);
    EXPECT_EQ(d->max_subscribe_subjects, s.max_subscribe_subjects);
    EXPECT_DOUBLE_EQ(d->max_address_messages_per_s, s.max_address_messages_per_s);
    EXPECT_EQ(d->address_message_burst, s.address_message_burst);
    const auto a = parse("[serve]\nmax_address_messages_per_s = 50.0\naddress_message_burst = 100\n", &err);
    ASSERT_TRUE(a) << err;
    EXPECT_DOUBLE_EQ(a->max_address_messages_per_s, 50.0);
    EXPECT_EQ(a->address_message_burst, 100u);
    EXPECT_FALSE(parse("[serve]\naddress_message_burst = 0\n", &err));

    const auto c = parse("[serve]\nmax_client_messages_per_s = 2.5\nclient_message_burst = 3\n", &err);
    ASSERT_TRUE(c) << err;
    EXPECT_DOUBLE_EQ(c->max_client_messages_per_s, 2.5);
    EXPECT_EQ(c->client_message_burst, 3u);
    EXPECT_EQ(parse("[serve]\nmax_subscribe_subjects = 8\n", &err)->max_subscribe_subjects, 8u);
    EXPECT_FALSE(parse("[serve]\nmax_subscribe_subjects = 0\n", &err));
    EXPECT_NE(err.find("serve.max_subscribe_subjects: must be between"), std::string::npos) << err;

    EXPECT_FALSE(parse("[serve]\nmax_client_messages_per_s = 0.0\n", &err));
    EXPECT_NE(err.find("test.toml:2: serve.max_client_messages_per_s: must be between"), std::string::npos) << err;
    EXPECT_FALSE(parse("[serve]\n\nclient_message_burst = 0\n", &err));
    EXPECT_NE(err.find("test.toml:3: serve.client_message_burst: must be between"), std::string::npos) << err;
}

TEST(Config, HttpSectionDefaultsValuesAndErrors) {
    std::string err;
    const auto d = parse_config(embedded_default_config(), "mocapd.toml", &err);
    ASSERT_TRUE(d) << err;
    const DaemonConfig s;
    EXPECT_TRUE(d->http_enabled);
    EXPECT_EQ(d->http_listen, (Endpoint{"0.0.0.0", 8080}));
    EXPECT_EQ(d->http_listen, s.http_listen);
    EXPECT_EQ(d->http_max_clients, s.http_max_clients);
    EXPECT_EQ(d->http_ws_queue_frames, s.http_ws_queue_frames);

    const auto c = parse(
        "[http]\nenabled = false\nlisten = \"127.0.0.1:9090\"\nmax_clients = 3\n"
        "ws_queue_frames = 2\n",
        &err);
    ASSERT_TRUE(c) << err;
    EXPECT_FALSE(c->http_enabled);
    EXPECT_EQ(c->http_listen, (Endpoint{"127.0.0.1", 9090}));
    EXPECT_EQ(c->http_max_clients, 3u);
    EXPECT_EQ(c->http_ws_queue_frames, 2u);

    EXPECT_FALSE(parse("[http]\nenabled = 1\n", &err));
    EXPECT_NE(err.find("test.toml:2: http.enabled: expected true or false"), std::string::npos) << err;
    EXPECT_FALSE(parse("[http]\n\nlisten = \"8080\"\n", &err));
    EXPECT_NE(err.find("test.toml:3: http.listen:"), std::string::npos) << err;
    EXPECT_FALSE(parse("[http]\nws_queue_frames = 0\n", &err));
    EXPECT_NE(err.find("test.toml:2: http.ws_queue_frames: must be between"), std::string::npos) << err;
    EXPECT_FALSE(parse("[http]\nport = 8080\n", &err));
    EXPECT_NE(err.find("test.toml:2: http.port: unknown key"), std::string::npos) << err;
}

}  // namespace
}  // namespace mocap::daemon

// ---- the one validation path of --check-config, start-up and reload (daemon/config_check.hpp)

#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "daemon/config_check.hpp"
#include "daemon/pipeline_config.hpp"

namespace mocap::daemon {
namespace {

/// A scratch directory for config files, removed at the end of the test.
class ConfigCheck : public ::testing::Test {
protected:
    void SetUp() override {
        char tmpl[] = "/tmp/mocap_config_check_XXXXXX";
        ASSERT_NE(::mkdtemp(tmpl), nullptr);
        dir_ = tmpl;
    }
    void TearDown() override { std::filesystem::remove_all(dir_); }

    std::string write(const std::string& name, const std::string& text) const {
        const auto path = (dir_ / name).string();
        std::ofstream(path) << text;
        return path;
    }

    /// The error of loading and checking `text` as a file ("" = accepted), as `mocapd
    /// --check-config` does (host names looked up).
    std::string refusal(const std::string& text) const {
        std::string err;
        return load_checked_config(write("c.toml", text), &err, HostLookups::kResolve) ? "" : err;
    }

    std::filesystem::path dir_;
};

// Each refusal names the file and the key an operator has to fix.
#define EXPECT_REFUSED(text, needle)                                                        \
    do {                                                                                    \
        const std::string e_ = refusal(text);                                               \
        EXPECT_NE(e_.find(needle), std::string::npos) << "error: \"" << e_ << "\"";         \
        EXPECT_EQ(e_.rfind((dir_ / "c.toml").string(), 0), 0u) << "names the file: " << e_; \
    } while (0)

TEST_F(ConfigCheck, EmbeddedDefaultAndShippedConfigsPass) {
    std::string err;
    EXPECT_TRUE(load_checked_config("", &err)) << err;
    std::size_t files = 0;
    for (const char* dir : {"/config", "/tests/fuzz/corpus/config"}) {
        for (const auto& e : std::filesystem::directory_iterator(std::string(MOCAP_SOURCE_DIR) + dir)) {
            if (e.path().extension() != ".toml") continue;
            ++files;
            EXPECT_TRUE(load_checked_config(e.path().string(), &err)) << err;
        }
    }
    EXPECT_GE(files, 3u) << "config/mocapd.toml and the fuzz corpus's two written configs";
}

TEST_F(ConfigCheck, DirectoryIsRefused) {
    std::string err;
    EXPECT_FALSE(load_checked_config(dir_.string(), &err));
    EXPECT_NE(err.find("not a regular file (a directory)"), std::string::npos) << err;
}

TEST_F(ConfigCheck, EmptyBlankAndCommentOnlyFilesAreRefused) {
    for (const char* text : {"", "  \n\t\n", "# only a comment\n\n   # another\n"}) {
        const std::string e = refusal(text);
        EXPECT_NE(e.find("has no settings"), std::string::npos) << "\"" << text << "\": " << e;
    }
    EXPECT_EQ(refusal("[log]\nlevel = \"info\"\n"), "") << "one setting is enough";
}

TEST_F(ConfigCheck, UnknownFilterNameIsRefused) {
    EXPECT_REFUSED("[filter]\nname = \"kalman\"\n", "filter.name: unknown filter \"kalman\"");
}

TEST_F(ConfigCheck, UnknownFilterInASegmentIsRefused) {
    EXPECT_REFUSED(
        "[[skeleton.segment]]\nname = \"pelvis\"\nnode = 1\nend_m = [0.0, 0.2, 0.0]\n"
        "[[skeleton.segment]]\nname = \"torso\"\nparent = \"pelvis\"\nnode = 2\noffset_m = [0.0, 0.2, 0.0]\n"
        "end_m = [0.0, 0.3, 0.0]\nfilter = \"kalmann\"\n",
        "skeleton.segment[1].filter: unknown filter \"kalmann\"");
}

TEST_F(ConfigCheck, UnknownFilterParameterIsRefused) {
    EXPECT_REFUSED("[filter]\nname = \"madgwick\"\nparams = { gamma = 0.1 }\n",
                   "filter.params.gamma: filter \"madgwick\" has no parameter \"gamma\"");
}

TEST_F(ConfigCheck, IllTypedFilterParameterIsRefused) {
    EXPECT_REFUSED("[filter]\nname = \"madgwick\"\nparams = { beta = \"abc\" }\n",
                   "filter.params.beta: parameter \"beta\" of filter \"madgwick\": cannot parse \"abc\"");
    EXPECT_REFUSED("[filter]\nname = \"madgwick\"\nparams = { beta = true }\n", "filter.params.beta:");
}

// `beta = 1e308` passed the check and made every output NaN: each number has a range.
TEST_F(ConfigCheck, FilterParameterOutsideItsRangeIsRefused) {
    EXPECT_REFUSED("[filter]\nname = \"madgwick\"\nparams = { beta = 1e308 }\n",
                   "filter.params.beta: parameter \"beta\" of filter \"madgwick\": ");
    EXPECT_REFUSED("[filter]\nname = \"pf\"\nparams = { particles = 1000000 }\n", "filter.params.particles:");
    EXPECT_REFUSED("[filter]\nparams = { tau_acc_s = -3.0 }\n", "filter.params.tau_acc_s:");
    EXPECT_EQ(refusal("[filter]\nname = \"madgwick\"\nparams = { beta = 0.5 }\n"), "");
}

TEST_F(ConfigCheck, ParameterThatASegmentsFilterDoesNotKnowIsRefused) {
    // [filter.params] apply to every segment's filter: a segment overriding the filter must
    // know them too (start-up built it and failed).
    EXPECT_REFUSED(
        "[filter]\nname = \"madgwick\"\nparams = { beta = 0.05 }\n"
        "[[skeleton.segment]]\nname = \"pelvis\"\nnode = 1\nend_m = [0.0, 0.2, 0.0]\nfilter = \"mahony\"\n",
        "filter.params.beta: filter \"mahony\" has no parameter \"beta\" (used by skeleton.segment[0].filter)");
}

TEST_F(ConfigCheck, HostNameIsRefused) {
    EXPECT_REFUSED("[serve]\npose_listen = \"no-such-host.invalid:7001\"\n",
                   "serve.pose_listen: host \"no-such-host.invalid\" must be an IPv4 or IPv6 address");
    EXPECT_REFUSED("[ingest]\nsink_listen = \"localhost:7000\"\n", "ingest.sink_listen: host \"localhost\"");
    EXPECT_REFUSED("[http]\nlisten = \"[fe80::1%no-such-if0]:8080\"\n", "http.listen: host");
    EXPECT_EQ(refusal("[http]\nlisten = \"[::1]:8080\"\n"), "");
}

TEST_F(ConfigCheck, TwoListenersOnOnePortAreRefused) {
    EXPECT_REFUSED("[serve]\npose_listen = \"127.0.0.1:7000\"\n",
                   "serve.pose_listen: 127.0.0.1:7000 collides with ingest.sink_listen (0.0.0.0:7000)");
    EXPECT_REFUSED("[http]\nlisten = \"0.0.0.0:7002\"\n", "http.listen: 0.0.0.0:7002 collides with outputs.bvh_listen");
    // Distinct addresses may share a port, and a listener that is off takes no port.
    EXPECT_EQ(refusal("[ingest]\nsink_listen = \"127.0.0.1:7000\"\n[serve]\npose_listen = \"127.0.0.2:7000\"\n"
                      "[outputs]\nbvh_listen = \"127.0.0.1:7009\"\n[http]\nlisten = \"127.0.0.1:7009\"\n"
                      "enabled = false\n"),
              "");
}

TEST_F(ConfigCheck, MoreServeThreadsThanSlotsAreRefused) {
    EXPECT_REFUSED("[outputs]\nbvh_max_clients = 2\nbvh_threads = 3\n",
                   "outputs.bvh_threads: 3 threads for 2 connection slots (outputs.bvh_max_clients)");
    EXPECT_REFUSED("[http]\nmax_clients = 1\nthreads = 2\n",
                   "http.threads: 2 threads for 1 connection slots (http.max_clients)");
    EXPECT_REFUSED("[http]\nthreads = 65\n", "http.threads:");
    // A port that is off serves nobody: its thread count does not matter.
    EXPECT_EQ(refusal("[outputs]\nbvh_live = false\nbvh_max_clients = 2\nbvh_threads = 3\n"), "");
    EXPECT_EQ(refusal("[outputs]\nbvh_threads = 4\n[http]\nthreads = 4\n"), "");
}

TEST_F(ConfigCheck, RawRecordIntoAMissingDirectoryIsRefused) {
    const std::string missing = (dir_ / "gone").string();
    EXPECT_REFUSED("[outputs]\nraw_record = true\nrecord_dir = \"" + missing + "\"\n",
                   "outputs.record_dir: \"" + missing + "\" is not a directory");
    EXPECT_EQ(refusal("[outputs]\nraw_record = false\nrecord_dir = \"" + missing + "\"\n"), "")
        << "not recording from start: the directory is only needed by a later record request";
    EXPECT_EQ(refusal("[outputs]\nraw_record = true\nrecord_dir = \"" + dir_.string() + "\"\n"), "");
}

TEST_F(ConfigCheck, RawRotationBelowTenSecondsOrOneMiBIsRefused) {
    EXPECT_REFUSED("[outputs]\nraw_rotate_s = 0.001\n",
                   "c.toml:2: outputs.raw_rotate_s: must be 0 (off) or between 10");
    EXPECT_REFUSED("[outputs]\nraw_rotate_mb = 0.001\n", "outputs.raw_rotate_mb: must be 0 (off) or between 1 ");
    EXPECT_EQ(refusal("[outputs]\nraw_rotate_s = 0\nraw_rotate_mb = 0\n"), "") << "0 = never";
    EXPECT_EQ(refusal("[outputs]\nraw_rotate_s = 10\nraw_rotate_mb = 1\n"), "");
}

TEST_F(ConfigCheck, BvhSubjectMustBeAConfiguredSubject) {
    EXPECT_REFUSED("[outputs]\nbvh_subject = 65000\n", "outputs.bvh_subject: 65000 is not a configured subject");
    EXPECT_REFUSED("[pipeline]\nmax_subjects = 4\n[outputs]\nbvh_subject = 5\n", "outputs.bvh_subject: 5");
    EXPECT_EQ(refusal("[pipeline]\nmax_subjects = 4\n[outputs]\nbvh_subject = 4\n"), "");
    EXPECT_EQ(refusal("[ingest]\n[[ingest.socketcan]]\ninterface = \"vcan0\"\nsubject = 200\n"
                      "[outputs]\nbvh_subject = 200\n"),
              "")
        << "a SocketCAN subject above max_subjects is configured too";
}

TEST_F(ConfigCheck, VmcDestinationsSubjectAndBonesAreChecked) {
    EXPECT_EQ(refusal("[vmc]\nenabled = true\ndestinations = [\"localhost:39539\", \"127.0.0.1:39540\"]\n"), "");
    EXPECT_REFUSED("[vmc]\nenabled = true\ndestinations = [\"127.0.0.1:1\", \"no-such-host.invalid:39539\"]\n",
                   "vmc.destinations[1]: cannot resolve host \"no-such-host.invalid\"");
    EXPECT_REFUSED("[vmc]\nenabled = true\nsubject = 65\n", "vmc.subject: 65 is not a configured subject");
    EXPECT_REFUSED("[vmc]\nenabled = true\n[vmc.bones]\npelvis = \"Hips\"\nhead = \"Hed\"\n",
                   "vmc.bones.head: \"Hed\" is not a Unity HumanBodyBones name");
    // A mapping is checked while the output is off too; a destination is resolved only when on.
    EXPECT_REFUSED("[vmc.bones]\ntrunk = \"Spine\"\n", "vmc.bones: the root segment \"pelvis\" must carry Hips");
    EXPECT_EQ(refusal("[vmc]\ndestinations = [\"no-such-host.invalid:39539\"]\n"), "");
    // Start-up and reload do not look names up (the DNS server may not be up yet; the sender
    // retries): the unresolvable name passes there, a destination that does not parse does not.
    std::string err;
    EXPECT_TRUE(load_checked_config(
        write("s.toml", "[vmc]\nenabled = true\ndestinations = [\"no-such-host.invalid:39539\"]\n"), &err))
        << err;
    EXPECT_FALSE(load_checked_config(write("p.toml", "[vmc]\nenabled = true\ndestinations = [\"no-port\"]\n"), &err));
    EXPECT_NE(err.find("vmc.destinations: \"no-port\": expected \"host:port\""), std::string::npos) << err;
}

TEST_F(ConfigCheck, SubjectIdBaseShiftsTheSinksSubjectsAndIsRangeChecked) {
    std::string err;
    const auto c = load_checked_config(write("b.toml",
                                             "[ingest]\nsubject_id_base = 4000000000\n"
                                             "[pipeline]\nmax_subjects = 3\n"
                                             "[[ingest.socketcan]]\ninterface = \"vcan0\"\nsubject = 7\n"),
                                       &err);
    ASSERT_TRUE(c) << err;
    EXPECT_EQ(c->subject_id_base, 4'000'000'000u);
    EXPECT_EQ(subject_ids_from_config(*c), (std::vector<std::uint32_t>{7, 4'000'000'001, 4'000'000'002, 4'000'000'003}))
        << "the sinks' ids follow the base; the bus keeps its own id; ascending";
    EXPECT_REFUSED("[ingest]\nsubject_id_base = 4000000001\n",
                   "c.toml:2: ingest.subject_id_base: must be between 0 and 4000000000");
    EXPECT_REFUSED("[ingest]\nsubject_id_base = -1\n", "ingest.subject_id_base: must be between 0 and 4000000000");
    EXPECT_REFUSED("[ingest]\nsubject_id_base = 1.5\n", "ingest.subject_id_base: expected an integer");
    EXPECT_EQ(
        refusal("[ingest]\nsubject_id_base = 1000\n[pipeline]\nmax_subjects = 4\n[outputs]\nbvh_subject = 1004\n"), "");
    EXPECT_REFUSED("[ingest]\nsubject_id_base = 1000\n[pipeline]\nmax_subjects = 4\n[outputs]\nbvh_subject = 4\n",
                   "outputs.bvh_subject: 4 is not a configured subject (0 = the first subject with a frame, or "
                   "ingest.subject_id_base + 1..pipeline.max_subjects = 1001..1004");
}

TEST_F(ConfigCheck, KeepalivePeriodIsOffOrWithinItsRange) {
    std::string err;
    auto c = load_checked_config(write("k.toml", "[ingest]\nkeepalive_period_s = 1.5\n"), &err);
    ASSERT_TRUE(c) << err;
    EXPECT_DOUBLE_EQ(c->keepalive_period_s, 1.5);
    c = load_checked_config(write("k0.toml", "[ingest]\nkeepalive_period_s = 0\n"), &err);
    ASSERT_TRUE(c) << err;
    EXPECT_DOUBLE_EQ(c->keepalive_period_s, 0.0) << "0 = stream version 1: no keepalive";
    EXPECT_REFUSED("[ingest]\nkeepalive_period_s = 0.001\n",
                   "ingest.keepalive_period_s: must be 0 (off) or between 0.02 and 60");
    EXPECT_REFUSED("[ingest]\nkeepalive_period_s = 61\n", "ingest.keepalive_period_s: must be 0 (off) or between");
}

TEST_F(ConfigCheck, SocketCanSubjectCollidingWithASinkOrAnotherBusIsRefused) {
    const std::string base = "[ingest]\nsubject_id_base = 1000\n[pipeline]\nmax_subjects = 4\n";
    const auto can = [](const char* iface, std::uint32_t subject) {
        return "[[ingest.socketcan]]\ninterface = \"" + std::string(iface) +
               "\"\nsubject = " + std::to_string(subject) + "\n";
    };
    EXPECT_REFUSED(base + can("vcan0", 1003),
                   "ingest.socketcan[0].subject: 1003 is a sink's subject id (ingest.subject_id_base + "
                   "1..pipeline.max_subjects = 1001..1004)");
    EXPECT_REFUSED(can("vcan0", 1), "ingest.socketcan[0].subject: 1 is a sink's subject id");
    EXPECT_REFUSED(base + can("vcan0", 3) + can("vcan1", 3),
                   "ingest.socketcan[1].subject: 3 is also ingest.socketcan[0]'s subject");
    EXPECT_EQ(refusal(base + can("vcan0", 1000) + can("vcan1", 1005) + can("vcan2", 4294967295u)), "")
        << "just outside the sinks' range, and the widest id";
}

TEST_F(ConfigCheck, BlankOrPaddedTokenIsRefused) {
    for (const char* token : {" ", "   \t", " secret-token-123", "secret-token-123\n", "secret\x01token"}) {
        std::string text = "[control]\ntoken = \"";
        for (const char ch : std::string(token)) {
            if (ch == '\n') {
                text += "\\n";
            } else if (ch == '\t') {
                text += "\\t";
            } else if (ch == '\x01') {
                text += "\\u0001";
            } else {
                text += ch;
            }
        }
        text += "\"\n";
        EXPECT_REFUSED(text, "c.toml:2: control.token: must not be blank");
    }
    EXPECT_EQ(refusal("[control]\ntoken = \"\"\n"), "") << "empty = control disabled";
    EXPECT_EQ(refusal("[control]\ntoken = \"a token with inner spaces\"\n"), "");
}

// Issue 13, item 8: with failed attempts limited to a few per second, a token of 16 random
// characters cannot be guessed; a shorter one is refused where every config is checked.
TEST_F(ConfigCheck, TokenShorterThanSixteenCharactersIsRefused) {
    EXPECT_REFUSED("[control]\ntoken = \"fifteen-chars-x\"\n",
                   "c.toml:2: control.token: must be at least 16 characters");
    EXPECT_REFUSED("[control]\ntoken = \"s3cret\"\n", "control.token: must be at least 16 characters");
    EXPECT_EQ(refusal("[control]\ntoken = \"sixteen-chars-xy\"\n"), "");
}

TEST_F(ConfigCheck, StatsIntervalBelowATenthOfASecondIsRefused) {
    EXPECT_REFUSED("[log]\nstats_interval_s = 0.001\n", "log.stats_interval_s: must be 0 (off) or between 0.1");
    EXPECT_EQ(refusal("[log]\nstats_interval_s = 0\n"), "");
}

TEST_F(ConfigCheck, ClusterDefaultsMatchTheStructAndOffNeedsNothing) {
    std::string err;
    const auto d = parse_config(embedded_default_config(), "mocapd.toml", &err);
    ASSERT_TRUE(d) << err;
    const DaemonConfig s;
    EXPECT_TRUE(d->cluster_nats_url.empty()) << "the README's run command needs no NATS server";
    EXPECT_EQ(d->cluster_site, s.cluster_site);
    EXPECT_EQ(d->cluster_host_id, s.cluster_host_id);
    EXPECT_EQ(d->cluster_allow_anonymous, s.cluster_allow_anonymous);
    EXPECT_EQ(d->cluster_raw_replicas, s.cluster_raw_replicas);
    EXPECT_EQ(d->cluster_queue_frames, s.cluster_queue_frames);
    EXPECT_EQ(d->cluster_raw_queue_samples, s.cluster_raw_queue_samples);
    EXPECT_REFUSED("[cluster]\nraw_queue_samples = 0\n", "c.toml:2: cluster.raw_queue_samples: must be between");
    EXPECT_EQ(refusal("[cluster]\nsite = \"hall\"\n"), "") << "no nats_url: credentials are not needed";
}

TEST_F(ConfigCheck, ClusterRefusesAnonymousUnlessAllowed) {
    const std::string url = "[cluster]\nnats_url = \"nats://127.0.0.1:4222\"\n";
    EXPECT_REFUSED(url, "cluster.nats_url: set credentials");
    EXPECT_EQ(refusal(url + "allow_anonymous = true\n"), "");
    EXPECT_EQ(refusal(url + "user = \"mocap\"\npassword = \"pw\"\n"), "");
    EXPECT_REFUSED(url + "user = \"mocap\"\n", "cluster.user: user and password go together");
    EXPECT_REFUSED(url + "user = \"mocap\"\npassword = \"pw\"\ncreds_file = \"/etc/hostname\"\n",
                   "cluster: give one kind of credentials");
    const std::string missing = (dir_ / "gone.creds").string();
    EXPECT_REFUSED(url + "creds_file = \"" + missing + "\"\n",
                   "cluster.creds_file: \"" + missing + "\" is not a readable");
    EXPECT_REFUSED(url + "allow_anonymous = true\ntls_cert_file = \"/etc/hostname\"\n",
                   "cluster.tls_cert_file: tls_cert_file and tls_key_file go together");
}

TEST_F(ConfigCheck, ClusterCalibrationKeyFileMustBeLongAndPrivate) {
    const std::string url = "[cluster]\nnats_url = \"nats://127.0.0.1:4222\"\nallow_anonymous = true\n";
    const std::string key = (dir_ / "calibration.key").string();
    const auto with_key = [&](const std::string& text, mode_t mode) {
        std::ofstream(key) << text;
        ::chmod(key.c_str(), mode);
        return url + "calibration_key_file = \"" + key + "\"\n";
    };
    const std::string good(40, 'k');
    EXPECT_EQ(refusal(with_key(good + "\n", 0600)), "");
    EXPECT_EQ(refusal(with_key(good, 0640)), "") << "its group (mocapd's) may read it";
    EXPECT_REFUSED(with_key(good, 0644), "cluster.calibration_key_file: " + key + ": others may read or write it");
    EXPECT_REFUSED(with_key(good, 0660), "others may read or write it, or its group may write it (mode 660");
    EXPECT_REFUSED(with_key("short", 0600), "the key is 5 bytes, at least 32 needed");
    EXPECT_REFUSED(url + "calibration_key_file = \"" + (dir_ / "gone.key").string() + "\"\n",
                   "cluster.calibration_key_file: cannot read");
}

TEST_F(ConfigCheck, ClusterSiteAndHostIdMustBeSubjectTokens) {
    for (const char* bad : {"", "a.b", "ven*", ">", "two words"}) {
        EXPECT_REFUSED(std::string("[cluster]\nsite = \"") + bad + "\"\n",
                       "c.toml:2: cluster.site: must be one NATS subject token");
    }
    EXPECT_REFUSED("[cluster]\nhost_id = \"h.1\"\n", "c.toml:2: cluster.host_id: must be");
    EXPECT_EQ(refusal("[cluster]\nsite = \"arena-2\"\nhost_id = \"rack_7\"\n"), "");
    DaemonConfig c;
    EXPECT_EQ(cluster_host_id(c).find_first_of(".*> \t"), std::string::npos) << cluster_host_id(c);
    EXPECT_FALSE(cluster_host_id(c).empty());
    c.cluster_host_id = "rack_7";
    EXPECT_EQ(cluster_host_id(c), "rack_7");
}

}  // namespace
}  // namespace mocap::daemon

namespace mocap::daemon {
namespace {

TEST(ConfigVmc, DefaultsAndValues) {
    std::string err;
    const auto d = parse_config("", "t.toml", &err);
    ASSERT_TRUE(d) << err;
    EXPECT_FALSE(d->vmc_enabled);
    EXPECT_EQ(d->vmc_destinations, std::vector<std::string>{"127.0.0.1:39539"});
    EXPECT_EQ(d->vmc_subject, 0u);
    EXPECT_TRUE(d->vmc_bones.empty());
    const auto c = parse_config(
        "[vmc]\nenabled = true\ndestinations = [\"studio-pc:39540\", \"[::1]:39539\"]\nsubject = 2\n"
        "[vmc.bones]\npelvis = \"Hips\"\n",
        "t.toml", &err);
    ASSERT_TRUE(c) << err;
    EXPECT_TRUE(c->vmc_enabled);
    EXPECT_EQ(c->vmc_destinations, (std::vector<std::string>{"studio-pc:39540", "[::1]:39539"}));
    EXPECT_EQ(c->vmc_subject, 2u);
    EXPECT_EQ(c->vmc_bones, (std::vector<std::pair<std::string, std::string>>{{"pelvis", "Hips"}}));
}

TEST(ConfigVmc, ErrorsNameKeyAndLine) {
    std::string err;
    EXPECT_FALSE(parse_config("[vmc]\ndestinations = [\"127.0.0.1\"]\n", "t.toml", &err));
    EXPECT_EQ(err, "t.toml:2: vmc.destinations: \"127.0.0.1\": expected \"host:port\"");
    EXPECT_FALSE(parse_config("[vmc]\ndestinations = [\"h:70000\"]\n", "t.toml", &err));
    EXPECT_EQ(err, "t.toml:2: vmc.destinations: \"h:70000\": port must be 1..65535");
    EXPECT_FALSE(parse_config("[vmc]\ndestinations = []\n", "t.toml", &err));
    EXPECT_EQ(err, "t.toml:2: vmc.destinations: list 1..16 receivers as \"host:port\"");
    EXPECT_FALSE(parse_config("[vmc.bones]\npelvis = 1\n", "t.toml", &err));
    EXPECT_EQ(err, "t.toml:2: vmc.bones.pelvis: expected a Unity HumanBodyBones name such as \"Hips\"");
}

}  // namespace
}  // namespace mocap::daemon
