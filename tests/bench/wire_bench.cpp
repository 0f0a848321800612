// wire_bench.cpp — CRC-32 of the sink packet: the slicing-by-8 form (mw_crc32, what the
// library uses) against the byte-at-a-time form it replaced (mw_crc32_update_bytewise), side
// by side over the same buffers. Sizes: a short packet, a 15-node raw packet (~640 B), one
// TCP segment, and a long run. bytes_per_second is the throughput; compare medians of
// repetitions (docs/performance.md):
//   build/tests/bench/wire_bench --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
#include <benchmark/benchmark.h>

#include <cstdint>
#include <random>
#include <vector>

#include "mocap_wire/mw_crc32.h"

namespace {

std::vector<std::uint8_t> random_bytes(std::size_t n) {
    std::mt19937 rng(7);
    std::uniform_int_distribution<int> byte(0, 255);
    std::vector<std::uint8_t> v(n);
    for (auto& b : v)
        b = static_cast<std::uint8_t>(byte(rng));
    return v;
}

template <std::uint32_t (*Crc)(std::uint32_t, const void*, std::size_t)>
void BM_Crc32(benchmark::State& state) {
    const auto n = static_cast<std::size_t>(state.range(0));
    const std::vector<std::uint8_t> data = random_bytes(n);
    std::uint32_t crc = MW_CRC32_INIT;
    for (auto _ : state) {
        crc = Crc(crc, data.data(), n);  // chained so no call can be dropped or hoisted
        benchmark::DoNotOptimize(crc);
    }
    state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations()) * state.range(0));
}

void BM_Crc32Bytewise(benchmark::State& state) {
    BM_Crc32<mw_crc32_update_bytewise>(state);
}
void BM_Crc32Slice8(benchmark::State& state) {
    BM_Crc32<mw_crc32_update>(state);
}

BENCHMARK(BM_Crc32Bytewise)->Arg(64)->Arg(640)->Arg(1460)->Arg(16384);
BENCHMARK(BM_Crc32Slice8)->Arg(64)->Arg(640)->Arg(1460)->Arg(16384);

}  // namespace

BENCHMARK_MAIN();
