// fuzz_make_seeds OUT_DIR — writes the generated seed inputs of three fuzz targets:
//   OUT_DIR/wire_stream/     the golden packets of docs/protocol.md and encoded batches,
//                            in the target's chunked form (length byte + bytes), whole,
//                            split small, behind garbage, with a broken CRC
//   OUT_DIR/reassembler/     CAN frame sequences (SYNC + ACCEL/GYRO/MAG, ATT, STATUS,
//                            counter wrap, reconnect) in the target's record form
//   OUT_DIR/client_session/  length-delimited ClientMessages: every request kind, with
//                            the harness token and without
// The config and BVH seeds are files copied by run_fuzzers.sh's --seed step instead.
// The committed corpora (tests/fuzz/corpus/) came from this program; rerun it only to
// regenerate them.
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "golden_vectors.h"
#include "mocap/v1/mocap.pb.h"
#include "mocap_wire/mocap_wire.h"
#include "serve/framing.hpp"

namespace {

using Bytes = std::vector<std::uint8_t>;
namespace fs = std::filesystem;

void write_file(const fs::path& dir, const std::string& name, const Bytes& b) {
    fs::create_directories(dir);
    std::ofstream out(dir / name, std::ios::binary);
    out.write(reinterpret_cast<const char*>(b.data()), static_cast<std::streamsize>(b.size()));
}

// --- wire_stream: chunked stream -------------------------------------------------------
Bytes chunked(const Bytes& stream, std::size_t chunk) {
    Bytes out;
    for (std::size_t i = 0; i < stream.size(); i += chunk) {
        const std::size_t n = std::min(chunk, stream.size() - i);
        out.push_back(static_cast<std::uint8_t>(n));
        out.insert(out.end(), stream.begin() + static_cast<std::ptrdiff_t>(i),
                   stream.begin() + static_cast<std::ptrdiff_t>(i + n));
    }
    return out;
}

mw_can_frame raw_frame(mw_function kind, std::uint8_t node, std::uint32_t counter, int base) {
    mw_message m{};
    m.function = kind;
    m.u.raw.kind = kind;
    m.u.raw.node_id = node;
    for (int i = 0; i < 3; ++i)
        m.u.raw.xyz[i] = static_cast<std::int16_t>(base + 100 * i);
    m.u.raw.counter_low = static_cast<std::uint16_t>(counter);
    mw_can_frame f{};
    mw_can_encode(&m, &f);
    return f;
}

mw_can_frame sync_frame(std::uint32_t counter) {
    mw_message m{};
    m.function = MW_FN_SYNC;
    m.u.sync.counter = counter;
    mw_can_frame f{};
    mw_can_encode(&m, &f);
    return f;
}

mw_can_frame att_frame(std::uint8_t node, std::uint32_t counter) {
    mw_message m{};
    m.function = MW_FN_ATTITUDE;
    m.u.attitude.node_id = node;
    m.u.attitude.q[0] = 0.9f;
    m.u.attitude.q[1] = 0.1f;
    m.u.attitude.q[2] = -0.3f;
    m.u.attitude.q[3] = 0.2f;
    m.u.attitude.counter_low = static_cast<std::uint16_t>(counter);
    mw_can_frame f{};
    mw_can_encode(&m, &f);
    return f;
}

mw_can_frame status_frame(std::uint8_t node, mw_accel_range ar) {
    mw_message m{};
    m.function = MW_FN_STATUS;
    m.u.status.node_id = node;
    m.u.status.state = MW_NODE_RUNNING;
    m.u.status.mode = MW_MODE_RAW;
    m.u.status.mag_present = true;
    m.u.status.accel_range = ar;
    m.u.status.gyro_range = MW_GYRO_500DPS;
    m.u.status.protocol_version = MW_CAN_PROTOCOL_VERSION;
    mw_can_frame f{};
    mw_can_encode(&m, &f);
    return f;
}

// One instant of `nodes` raw nodes.
std::vector<mw_can_frame> instant(std::uint32_t counter, std::uint8_t nodes) {
    std::vector<mw_can_frame> v{sync_frame(counter)};
    for (std::uint8_t n = 1; n <= nodes; ++n) {
        v.push_back(raw_frame(MW_FN_ACCEL, n, counter, 2048));
        v.push_back(raw_frame(MW_FN_GYRO, n, counter, -15));
        v.push_back(raw_frame(MW_FN_MAG, n, counter, 200));
    }
    return v;
}

Bytes packet(const std::vector<mw_can_frame>& frames, std::uint32_t sequence) {
    std::vector<mw_stamped_frame> stamped;
    for (std::size_t i = 0; i < frames.size(); ++i) {
        stamped.push_back({static_cast<std::uint16_t>(i * 20), frames[i]});
    }
    const mw_packet_header h{3, sequence, 1'000'000ull * sequence};
    Bytes out(MW_PACKET_MAX_SIZE);
    const std::int32_t n = mw_packet_encode(&h, stamped.data(), stamped.size(), out.data(), out.size());
    out.resize(n > 0 ? static_cast<std::size_t>(n) : 0);
    return out;
}

void wire_seeds(const fs::path& dir) {
    Bytes all;
    for (std::size_t i = 0; i < golden_packet_count; ++i) {
        const Bytes p(golden_packets[i].bytes, golden_packets[i].bytes + golden_packets[i].size);
        write_file(dir, "golden_" + std::to_string(i) + "_whole", chunked(p, 255));
        write_file(dir, "golden_" + std::to_string(i) + "_split7", chunked(p, 7));
        all.insert(all.end(), p.begin(), p.end());
    }
    Bytes two = packet(instant(41, 3), 1);
    const Bytes second = packet(instant(42, 3), 2);
    two.insert(two.end(), {'M', 'C', 'A', 0x00, 0x13});  // a false magic between packets
    two.insert(two.end(), second.begin(), second.end());
    write_file(dir, "two_packets_garbage_between", chunked(two, 64));
    Bytes bad_crc = packet(instant(43, 2), 3);
    bad_crc.back() ^= 0x5A;
    write_file(dir, "bad_crc", chunked(bad_crc, 255));
    write_file(dir, "golden_all_split1", chunked(all, 1));
}

// --- reassembler: op + id + dlc + 8 data + time step --------------------------------------
void add_frame(Bytes& out, const mw_can_frame& f, std::uint8_t dt = 10) {
    out.push_back(0);
    out.push_back(static_cast<std::uint8_t>(f.id & 0xFF));
    out.push_back(static_cast<std::uint8_t>(f.id >> 8));
    out.push_back(f.dlc);
    out.insert(out.end(), f.data, f.data + 8);
    out.push_back(dt);
}

void reassembler_seeds(const fs::path& dir) {
    Bytes steady;
    add_frame(steady, status_frame(1, MW_ACCEL_4G));
    for (std::uint32_t c = 100; c < 106; ++c) {
        for (const auto& f : instant(c, 3))
            add_frame(steady, f);
    }
    write_file(dir, "raw_three_nodes", steady);

    Bytes wrap;
    for (std::uint32_t c = 0xFFFFFFFDu; c != 3u; ++c) {
        for (const auto& f : instant(c, 2))
            add_frame(wrap, f);
    }
    write_file(dir, "counter_wrap", wrap);

    Bytes att;
    for (std::uint32_t c = 5000; c < 5006; ++c) {
        add_frame(att, sync_frame(c));
        add_frame(att, att_frame(4, c));
        add_frame(att, raw_frame(MW_FN_ACCEL, 4, c, 1000));
    }
    write_file(dir, "attitude", att);

    Bytes reconnect;
    for (const auto& f : instant(900, 2))
        add_frame(reconnect, f);
    reconnect.push_back(7);  // reset_stream
    for (const auto& f : instant(3, 2))
        add_frame(reconnect, f);
    // Out of order and duplicated parts.
    const auto late = instant(4, 1);
    add_frame(reconnect, late[3]);
    add_frame(reconnect, late[1]);
    add_frame(reconnect, late[1]);
    add_frame(reconnect, late[0]);
    add_frame(reconnect, late[2]);
    write_file(dir, "reconnect_out_of_order", reconnect);
}

// --- client_session: delimited ClientMessages ---------------------------------------------
void add_message(std::string& out, const mocap::v1::ClientMessage& m) {
    mocap::serve::append_delimited(m, out);
}

void session_seeds(const fs::path& dir) {
    using mocap::v1::ClientMessage;
    auto save = [&](const std::string& name, const std::string& s) {
        write_file(dir, name, Bytes(s.begin(), s.end()));
    };
    std::string s;
    ClientMessage sub;
    sub.mutable_subscribe()->add_subject_ids(2);
    sub.mutable_subscribe()->add_subject_ids(1);
    sub.mutable_subscribe()->add_subject_ids(2);
    sub.mutable_subscribe()->set_decimation(3);
    sub.mutable_subscribe()->set_fields(5);
    add_message(s, sub);
    save("subscribe", s);

    ClientMessage ping;
    ping.mutable_ping()->set_nonce(77);
    ping.mutable_ping()->set_client_time_us(123456789);
    ClientMessage stats;
    stats.mutable_stats_request()->set_request_id(9);
    std::string mixed;
    add_message(mixed, ping);
    add_message(mixed, stats);
    add_message(mixed, sub);
    add_message(mixed, ping);
    save("ping_stats_subscribe_ping", mixed);

    std::string control;
    ClientMessage c;
    c.mutable_control()->set_request_id(1);
    c.mutable_control()->set_token("fuzz-token");
    c.mutable_control()->mutable_calibrate()->set_subject_id(1);
    c.mutable_control()->mutable_calibrate()->set_pose(mocap::v1::POSE_N);
    add_message(control, c);
    c.mutable_control()->mutable_start_recording()->set_path("/tmp/take.bvh");
    add_message(control, c);
    c.mutable_control()->mutable_stop_recording();
    add_message(control, c);
    c.mutable_control()->mutable_reload();
    add_message(control, c);
    c.mutable_control()->clear_action();
    add_message(control, c);
    c.mutable_control()->set_token("wrong");
    c.mutable_control()->mutable_reload();
    add_message(control, c);
    c.mutable_control()->clear_token();
    add_message(control, c);
    save("control_all_actions", control);

    std::string empty_body;
    add_message(empty_body, ClientMessage());
    save("unknown_body", empty_body);

    save("oversized_prefix", std::string("\xff\xff\xff\x0f", 4));
    save("bad_prefix", std::string("\xff\xff\xff\xff\xff\xff", 6));
    std::string flood;
    for (int i = 0; i < 50; ++i)
        add_message(flood, ping);
    save("ping_flood", flood);
}

}  // namespace

int main(int argc, char** argv) {
    if (argc != 2) {
        std::fprintf(stderr, "usage: %s OUT_DIR\n", argv[0]);
        return 2;
    }
    const fs::path out(argv[1]);
    wire_seeds(out / "wire_stream");
    reassembler_seeds(out / "reassembler");
    session_seeds(out / "client_session");
    return 0;
}
