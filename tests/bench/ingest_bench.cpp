// ingest_bench.cpp — the ingest thread's per-sample work without the socket: one sink packet
// of a 15-node raw body (SYNC + 45 ACCEL/GYRO/MAG frames, one 100 Hz instant, 15 samples)
//   - BM_ReassembleInstant15: its CAN frames through FrameReassembler::on_frame (frame
//     decode, the instant's slots, scaling, the sample callback and the reassembly counters);
//   - BM_IngestPacket15: the packet's bytes through mw_stream_decoder_feed (framing and the
//     CRC-32) and then the reassembler, as SinkListener does per TCP read.
// items_per_second counts samples. 4096 consecutive instants are built once and cycled; the
// SYNC counter steps back once per cycle, which the reassembler takes as a new stream.
//   ingest_bench --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
#include <benchmark/benchmark.h>

#include <cstdint>
#include <cstdlib>
#include <memory>
#include <vector>

#include "ingest/frame_reassembler.hpp"
#include "mocap_wire/mocap_wire.h"

namespace mocap::ingest {
namespace {

constexpr std::uint8_t kNodes = 15;
constexpr std::uint32_t kInstants = 4096;

struct Instants {
    std::vector<mw_packet_header> headers;
    std::vector<std::vector<mw_stamped_frame>> frames;  // per instant
    std::vector<std::vector<std::uint8_t>> bytes;       // per instant: the encoded packet
};

const Instants& instants() {
    static const Instants all = [] {
        Instants in;
        for (std::uint32_t k = 0; k < kInstants; ++k) {
            const mw_packet_header h = {1u, k, std::uint64_t{k} * 10'000u};
            std::vector<mw_stamped_frame> f;
            mw_stamped_frame s{};
            const mw_sync sync = {k};
            if (mw_sync_encode(&sync, &s.frame) != MW_OK) std::abort();
            f.push_back(s);
            for (std::uint8_t node = 1; node <= kNodes; ++node) {
                for (unsigned part = 0; part < 3; ++part) {
                    const mw_raw r = {static_cast<mw_function>(MW_FN_ACCEL + part),
                                      node,
                                      {100, -200, 2048},
                                      static_cast<std::uint16_t>(k)};
                    s.offset_us = static_cast<std::uint16_t>(200u + node * 60u + part * 20u);
                    if (mw_raw_encode(&r, &s.frame) != MW_OK) std::abort();
                    f.push_back(s);
                }
            }
            std::vector<std::uint8_t> b(mw_packet_size(f.data(), f.size()));
            if (mw_packet_encode(&h, f.data(), f.size(), b.data(), b.size()) != static_cast<std::int32_t>(b.size()))
                std::abort();
            in.headers.push_back(h);
            in.frames.push_back(std::move(f));
            in.bytes.push_back(std::move(b));
        }
        return in;
    }();
    return all;
}

void BM_ReassembleInstant15(benchmark::State& state) {
    const Instants& in = instants();
    ReassemblyCounters counters;
    std::uint64_t samples = 0;
    FrameReassembler r(1, {}, counters, [&samples](const SegmentSample&) { ++samples; });
    std::uint32_t k = 0;
    for (auto _ : state) {
        const auto ts = static_cast<std::int64_t>(in.headers[k].timestamp_us);
        for (const mw_stamped_frame& f : in.frames[k])
            r.on_frame(f.frame, ts + f.offset_us, ts, ts + 1000);
        k = (k + 1) % kInstants;
    }
    benchmark::DoNotOptimize(samples);
    state.SetItemsProcessed(static_cast<std::int64_t>(counters.samples.value()));
}
BENCHMARK(BM_ReassembleInstant15);

void BM_IngestPacket15(benchmark::State& state) {
    const Instants& in = instants();
    ReassemblyCounters counters;
    std::uint64_t samples = 0;
    FrameReassembler r(1, {}, counters, [&samples](const SegmentSample&) { ++samples; });
    auto decoder = std::make_unique<mw_stream_decoder>();
    auto packet = std::make_unique<mw_packet>();
    mw_stream_decoder_init(decoder.get());
    std::uint32_t k = 0;
    for (auto _ : state) {
        const std::vector<std::uint8_t>& b = in.bytes[k];
        std::size_t used = 0;
        if (mw_stream_decoder_feed(decoder.get(), b.data(), b.size(), &used, packet.get()) != MW_STREAM_PACKET) {
            state.SkipWithError("packet not decoded");
            break;
        }
        const auto ts = static_cast<std::int64_t>(packet->header.timestamp_us);
        for (std::uint16_t i = 0; i < packet->frame_count; ++i)
            r.on_frame(packet->frames[i].frame, ts + packet->frames[i].offset_us, ts, ts + 1000);
        k = (k + 1) % kInstants;
    }
    benchmark::DoNotOptimize(samples);
    state.SetItemsProcessed(static_cast<std::int64_t>(counters.samples.value()));
}
BENCHMARK(BM_IngestPacket15);

}  // namespace
}  // namespace mocap::ingest

BENCHMARK_MAIN();
