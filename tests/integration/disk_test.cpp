// The real mocapd on loopback against a hostile file system (docs/reliability.md, "Disk
// faults"): a FIFO where a calibration file should be, a record directory that fills up
// (a small tmpfs, mounted when the test runs as root, as CI does) and one that disappears.
#include <sys/mount.h>
#include <sys/stat.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <map>
#include <sstream>
#include <thread>

#include "harness.hpp"
#include "pose_client.hpp"

namespace mocap::itest {
namespace {

using namespace std::chrono_literals;
namespace fs = std::filesystem;

constexpr const char* kToken = "disk-test-token-0123456789";

/// Polls `done` every 20 ms until it holds or `limit` passes.
template <typename Done>
bool wait_until(Done done, std::chrono::milliseconds limit) {
    const auto end = std::chrono::steady_clock::now() + limit;
    while (std::chrono::steady_clock::now() < end) {
        if (done()) return true;
        std::this_thread::sleep_for(20ms);
    }
    return done();
}

class Disk : public ::testing::Test {
protected:
    void TearDown() override {
        if (!daemon_) return;
        if (HasFailure()) std::cerr << "--- mocapd log ---\n" << daemon_->log();
        const int rc = daemon_->stop(10s);
        EXPECT_EQ(rc, 0) << "mocapd must drain and exit 0 on SIGTERM";
    }

    void start_daemon(const std::string& outputs_extra = "") {
        sink_port_ = free_port();
        pose_port_ = free_port();
        std::ostringstream cfg;
        cfg << "[log]\nlevel = \"info\"\nstats_interval_s = 0\n"
            << "[ingest]\nsink_listen = \"127.0.0.1:" << sink_port_ << "\"\n"
            << "[pipeline]\nworkers = 2\nmax_subjects = 4\n"
            << "[skeleton]\ncalibration_dir = \"" << calibration_dir_ << "\"\n"
            << "[serve]\npose_listen = \"127.0.0.1:" << pose_port_ << "\"\n"
            << "[control]\ntoken = \"" << kToken << "\"\n"
            << "[outputs]\nbvh_listen = \"127.0.0.1:" << free_port() << "\"\nbvh_subject = 1\n"
            << "record_dir = \"" << record_dir_ << "\"\n"
            << outputs_extra << "[http]\nlisten = \"127.0.0.1:" << free_port() << "\"\n";
        write_file(dir_.file("mocapd.toml"), cfg.str());
        daemon_ = std::make_unique<Process>(std::vector<std::string>{MOCAPD_BIN, "--config", dir_.file("mocapd.toml")},
                                            dir_.file("mocapd.log"), dir_.path().string());
        ASSERT_TRUE(wait_for_port(pose_port_, 20s)) << daemon_->log();
        ASSERT_TRUE(wait_for_port(sink_port_, 20s)) << daemon_->log();
    }

    TempDir dir_;
    std::string calibration_dir_ = dir_.path().string();
    std::string record_dir_ = dir_.path().string();
    std::uint16_t sink_port_ = 0, pose_port_ = 0;
    std::unique_ptr<Process> daemon_;
};

// A FIFO named like a calibration file made start-up block in open() forever, with no log
// line. Now it is opened non-blocking, found not to be a regular file, logged and skipped.
TEST_F(Disk, FifoInTheCalibrationDirectoryIsLoggedAndSkipped) {
    const fs::path cal = dir_.path() / "calibration";
    fs::create_directories(cal);
    calibration_dir_ = cal.string();
    const std::string fifo = (cal / "calibration-subject-1.toml").string();
    ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0) << fifo;
    ASSERT_NO_FATAL_FAILURE(start_daemon());
    EXPECT_TRUE(wait_until([&] { return daemon_->log().find("FIFO") != std::string::npos; }, 10s));
    const std::string log = daemon_->log();
    EXPECT_NE(log.find("ignoring " + fifo + ": a FIFO, not a regular file: skipped"), std::string::npos) << log;
}

}  // namespace
}  // namespace mocap::itest
