// Fuzz target: CAN frame reassembly (server/ingest FrameReassembler) fed arbitrary frames.
//
// Input: records of one op byte and its operands.
//   op % 8 == 7: reset_stream() (a sink reconnect)
//   otherwise:   a CAN frame: id (2 bytes, not masked), dlc (1 byte, not clamped: the
//                reassembler must reject DLC > 8 itself), 8 data bytes, and a 1-byte time
//                step; the op byte's high bits pick the receive-time jitter.
// Every emitted sample must have finite values (IMU and node quaternion), a non-zero
// SYNC, and per node strictly increasing SYNC (also across reset_stream(), as the header
// promises). Counters must only go up and frames must equal the frames fed.
#include <array>
#include <cmath>

#include "fuzz_target.hpp"
#include "ingest/frame_reassembler.hpp"

namespace {

struct Checker {
    std::array<std::uint64_t, 256> last_sync{};
    std::uint64_t emitted = 0;

    void on_sample(const mocap::SegmentSample& s) {
        ++emitted;
        MOCAP_FUZZ_CHECK(s.sync != 0, "sample with SYNC 0");
        MOCAP_FUZZ_CHECK(s.sync > last_sync[s.node_id], "SYNC not increasing per node");
        last_sync[s.node_id] = s.sync;
        for (std::size_t i = 0; i < 3; ++i) {
            MOCAP_FUZZ_CHECK(std::isfinite(s.imu.gyro_rad_s[i]), "gyro not finite");
            MOCAP_FUZZ_CHECK(std::isfinite(s.imu.accel_m_s2[i]), "accel not finite");
            MOCAP_FUZZ_CHECK(std::isfinite(s.imu.mag_ut[i]), "mag not finite");
        }
        double norm2 = 0;
        for (double q : s.node_q_wxyz) {
            MOCAP_FUZZ_CHECK(std::isfinite(q), "node quaternion not finite");
            norm2 += q * q;
        }
        if (s.has_node_quat) {
            MOCAP_FUZZ_CHECK(std::fabs(norm2 - 1.0) < 1e-3, "node quaternion not unit");
        }
    }
};

}  // namespace

MOCAP_FUZZ_ENTRY(reassembler) {
    mocap::ingest::ReassemblyCounters counters;
    Checker checker;
    mocap::ingest::FrameReassembler reassembler(7, {}, counters,
                                                [&checker](const mocap::SegmentSample& s) { checker.on_sample(s); });

    mocap::fuzz::ByteReader in(data, size);
    std::int64_t t_us = 1'000'000;
    std::uint64_t frames = 0;
    while (!in.empty()) {
        const std::uint8_t op = in.u8();
        if (op % 8 == 7) {
            reassembler.reset_stream();
            continue;
        }
        mw_can_frame f{};
        f.id = in.u16();
        f.dlc = in.u8();
        for (auto& b : f.data)
            b = in.u8();
        t_us += in.u8() * 100;
        const std::int64_t jitter = (op >> 3) * 7;
        reassembler.on_frame(f, t_us, t_us - 500, t_us + jitter);
        ++frames;
    }
    MOCAP_FUZZ_CHECK(counters.frames.value() == frames, "frames counter");
    MOCAP_FUZZ_CHECK(counters.samples.value() + counters.attitude_samples.value() == checker.emitted,
                     "sample counters != samples emitted");
    MOCAP_FUZZ_CHECK(counters.samples_no_mag.value() <= counters.samples.value(), "samples_no_mag > samples");
    return 0;
}
