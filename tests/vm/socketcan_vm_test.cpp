// Runs inside a throw-away VM (tests/vm/run_socketcan_vm.sh) whose kernel has vcan: drives
// the real SocketCanReader against a real kernel's SocketCAN and prints one result line
// "SOCKETCAN-VM-RESULT PASS|FAIL". Usage: socketcan_vm_test IFACE
#include <linux/can.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <vector>

#include "ingest/socketcan_reader.hpp"
#include "mocap_wire/mw_can.h"

namespace {

using namespace mocap;

class WallClock : public Clock {
public:
    std::int64_t now_us() const noexcept override {
        return std::chrono::duration_cast<std::chrono::microseconds>(
                   std::chrono::system_clock::now().time_since_epoch())
            .count();
    }
};

int failures = 0;
void check(bool ok, const char* what) {
    std::printf("%s %s\n", ok ? "ok  " : "FAIL", what);
    if (!ok) ++failures;
}

int open_sender(const char* iface) {
    const int fd = ::socket(PF_CAN, SOCK_RAW, CAN_RAW);
    if (fd < 0) return -1;
    const int on = 1;
    ::setsockopt(fd, SOL_CAN_RAW, CAN_RAW_FD_FRAMES, &on, sizeof on);
    sockaddr_can addr{};
    addr.can_family = AF_CAN;
    addr.can_ifindex = static_cast<int>(::if_nametoindex(iface));
    if (::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) < 0) return -1;
    return fd;
}

bool send_classic(int fd, const mw_can_frame& f, canid_t flags = 0) {
    can_frame c{};
    c.can_id = f.id | flags;
    c.len = f.dlc;
    std::memcpy(c.data, f.data, f.dlc);
    return ::write(fd, &c, sizeof c) == static_cast<ssize_t>(sizeof c);
}

std::vector<mw_can_frame> instant(std::uint32_t counter, std::uint8_t nodes) {
    std::vector<mw_can_frame> out;
    mw_can_frame f{};
    mw_sync s{counter};
    mw_sync_encode(&s, &f);
    out.push_back(f);
    for (std::uint8_t n = 1; n <= nodes; ++n) {
        for (mw_function k : {MW_FN_ACCEL, MW_FN_GYRO, MW_FN_MAG}) {
            mw_raw r{};
            r.kind = k;
            r.node_id = n;
            r.xyz[0] = static_cast<std::int16_t>(n);
            r.xyz[2] = 2048;  // 1 g at ±16 g
            r.counter_low = static_cast<std::uint16_t>(counter);
            mw_raw_encode(&r, &f);
            out.push_back(f);
        }
    }
    return out;
}

}  // namespace

int main(int argc, char** argv) {
    const char* iface = argc > 1 ? argv[1] : "vcan0";
    asio::io_context io;
    WallClock clock;
    std::vector<SegmentSample> samples;
    ingest::SocketCanConfig cfg;
    cfg.interface = iface;
    cfg.subject = 5;
    ingest::SocketCanReader reader(io, cfg, clock, [&](const SegmentSample& s) { samples.push_back(s); });
    std::string err;
    // start() binds before returning, so nothing sent afterwards is lost to a late bind.
    check(reader.start(&err), "reader binds the interface");
    if (!err.empty()) std::printf("  %s\n", err.c_str());
    const int tx = open_sender(iface);
    check(tx >= 0, "sender socket");
    if (failures) {
        std::printf("SOCKETCAN-VM-RESULT FAIL\n");
        return 1;
    }
    const auto value = [&](const char* name) { return reader.counters().value(name).value_or(0); };

    // Phase 1: 200 instants x 15 nodes, paced so the receive queue never overflows: after each
    // instant, run the reader until it has read every frame sent so far.
    constexpr std::uint32_t kInstants = 200;
    constexpr std::uint8_t kNodes = 15;
    std::uint64_t sent = 0;
    const std::int64_t t0 = clock.now_us();
    for (std::uint32_t i = 0; i < kInstants; ++i) {
        for (const auto& f : instant(0xFFFFFFA0u + i, kNodes))
            sent += send_classic(tx, f) ? 1 : 0;
        const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(5);
        while (value("frames_read") < sent && std::chrono::steady_clock::now() < until)
            io.run_one_for(std::chrono::milliseconds(50));
    }
    const std::int64_t t1 = clock.now_us();
    check(sent == kInstants * (1 + 3 * kNodes), "every frame written to vcan");
    check(value("frames_read") == sent, "every frame read back through SocketCAN");
    check(samples.size() == kInstants * kNodes, "one sample per node per instant");
    check(value("sync_wraps") == 1, "32-bit SYNC wrap seen once");
    bool ordered = true, stamped = true, scaled = true;
    for (std::size_t k = kNodes; k < samples.size(); ++k) {
        if (samples[k].sync != samples[k - kNodes].sync + 1) ordered = false;
    }
    for (const auto& s : samples) {
        if (s.imu.t_us < t0 - 1000 || s.imu.t_us > t1 + 1000) stamped = false;
        if (std::abs(s.imu.accel_m_s2[2] - 9.80665) > 1e-3 || s.subject_id != 5) scaled = false;
    }
    check(ordered, "sync counters consecutive per node across the wrap");
    check(stamped, "kernel receive timestamps (SO_TIMESTAMP) used as sample times");
    check(scaled, "samples scaled to SI and tagged with the configured subject");

    // Phase 2: frames that are not ours.
    const std::uint64_t before = value("frames_read");
    canfd_frame fd{};
    fd.can_id = 0x123;
    fd.len = 12;
    fd.flags = CANFD_BRS;
    const bool fd_ok = ::write(tx, &fd, sizeof fd) == static_cast<ssize_t>(sizeof fd);
    mw_can_frame rtr{};
    rtr.id = 0x081;
    send_classic(tx, rtr, CAN_RTR_FLAG);
    mw_can_frame eff{};
    eff.id = 0x0AB;
    eff.dlc = 2;
    send_classic(tx, eff, CAN_EFF_FLAG);
    mw_can_frame reserved{};
    reserved.id = MW_CAN_ID(20, 1);
    reserved.dlc = 8;
    send_classic(tx, reserved);
    const std::uint64_t expect = before + (fd_ok ? 4 : 3);
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(5);
    while (value("frames_read") < expect && std::chrono::steady_clock::now() < until)
        io.run_one_for(std::chrono::milliseconds(50));
    check(fd_ok, "CAN FD frame accepted by the FD-capable interface (mtu 72)");
    check(value("fd_frames") == 1 && value("foreign_frames") == 2, "FD payload and 29-bit ID counted as foreign");
    check(value("rtr_frames") == 1, "RTR frame counted");
    check(value("malformed_frames") == 1, "reserved CAN ID counted as malformed");

    // Phase 3: the reader does not run while a burst arrives: the kernel's receive queue
    // overflows and SO_RXQ_OVFL reports the drops on the next frame read.
    for (std::uint32_t i = 0; i < 200; ++i) {
        for (const auto& f : instant(i, kNodes))
            send_classic(tx, f);
    }
    for (int k = 0; k < 20; ++k)
        io.run_one_for(std::chrono::milliseconds(20));
    // The kernel stamps each queued frame with the socket's drop total at queue time, so
    // the drops show on the first frame queued after the overflow.
    send_classic(tx, instant(1000, 0)[0]);
    for (int k = 0; k < 20; ++k)
        io.run_one_for(std::chrono::milliseconds(20));
    std::printf("  kernel_drops = %llu\n", static_cast<unsigned long long>(value("kernel_drops")));
    check(value("kernel_drops") > 0, "kernel queue overflow surfaced as kernel_drops (SO_RXQ_OVFL)");

    reader.stop();
    ::close(tx);
    std::printf("SOCKETCAN-VM-RESULT %s\n", failures == 0 ? "PASS" : "FAIL");
    return failures == 0 ? 0 : 1;
}
