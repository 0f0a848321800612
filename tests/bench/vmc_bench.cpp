// vmc_bench — the VMC output's cost per frame for the default 15-segment body
// (docs/outputs.md, "VMC"): the producer's publish() on the assembler thread, and on the
// sender thread the conversion to Unity's frame, the liblo bundle and one send() on loopback.
//   build/tests/bench/vmc_bench --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
#include <benchmark/benchmark.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <random>

#include "serve/vmc_osc.hpp"
#include "serve/vmc_rig.hpp"
#include "serve/vmc_sender.hpp"
#include "skeleton/body_model.hpp"

namespace {

using namespace mocap;

serve::VmcRig rig() {
    std::string error;
    return *serve::VmcRig::build(skeleton::default_body_model(), {}, &error);
}

skeleton::SkeletonPose walking_pose() {
    std::mt19937 rng(1);
    std::normal_distribution<double> n(0.0, 0.3);
    skeleton::SkeletonPose p;
    p.segment_count = 15;
    for (std::size_t s = 0; s < 15; ++s) {
        math::Quat q(1.0, n(rng), n(rng), n(rng));
        q.normalize();
        p.q_world_segment_wxyz[s] = {q.w(), q.x(), q.y(), q.z()};
    }
    p.position_m[0] = {0.3, -0.2, 0.93};
    return p;
}

void BM_VmcConvert(benchmark::State& state) {
    const auto r = rig();
    const auto pose = walking_pose();
    serve::VmcPose out;
    for (auto _ : state) {
        r.convert(pose, out);
        benchmark::DoNotOptimize(out);
    }
}
BENCHMARK(BM_VmcConvert);

void BM_VmcEncodeBundle(benchmark::State& state) {
    const auto r = rig();
    serve::VmcPose out;
    r.convert(walking_pose(), out);
    std::vector<char> bytes;
    for (auto _ : state) {
        benchmark::DoNotOptimize(serve::encode_vmc_bundle(r, out, {true, true, 1.0f}, bytes));
    }
    state.counters["bytes"] = static_cast<double>(bytes.size());
}
BENCHMARK(BM_VmcEncodeBundle);

// Convert, encode and send() one bundle on a connected UDP socket to a loopback port that a
// bound socket drains nowhere (the kernel discards what overflows its buffer).
void BM_VmcConvertEncodeSend(benchmark::State& state) {
    const auto r = rig();
    const auto pose = walking_pose();
    const int rx = ::socket(AF_INET, SOCK_DGRAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    ::bind(rx, reinterpret_cast<sockaddr*>(&a), sizeof a);
    socklen_t len = sizeof a;
    ::getsockname(rx, reinterpret_cast<sockaddr*>(&a), &len);
    const int tx = ::socket(AF_INET, SOCK_DGRAM | SOCK_NONBLOCK, 0);
    ::connect(tx, reinterpret_cast<sockaddr*>(&a), sizeof a);
    serve::VmcPose out;
    std::vector<char> bytes;
    char sink[4096];
    for (auto _ : state) {
        r.convert(pose, out);
        serve::encode_vmc_bundle(r, out, {true, true, 1.0f}, bytes);
        benchmark::DoNotOptimize(::send(tx, bytes.data(), bytes.size(), MSG_DONTWAIT));
        state.PauseTiming();
        while (::recv(rx, sink, sizeof sink, MSG_DONTWAIT) > 0) {
        }
        state.ResumeTiming();
    }
    ::close(tx);
    ::close(rx);
}
BENCHMARK(BM_VmcConvertEncodeSend);

// What the assembler thread pays: the subject check and the pose copy into the ring (the
// sender thread is not started, so the ring is emptied by the benchmark between batches).
void BM_VmcPublish(benchmark::State& state) {
    struct ZeroClock final : Clock {
        [[nodiscard]] std::int64_t now_us() const noexcept override { return 0; }
    } clock;
    const auto pose = walking_pose();
    SubjectFrame frame;
    frame.subject_id = 1;
    frame.segment_count = 15;
    for (auto _ : state) {
        state.PauseTiming();
        serve::VmcSenderConfig config;
        config.destinations = {{"127.0.0.1", 39539}};
        config.queue_frames = 1024;
        serve::VmcSender sender(config, rig(), clock);
        state.ResumeTiming();
        for (int i = 0; i < 1000; ++i)
            sender.publish(frame, pose);
    }
    state.SetItemsProcessed(state.iterations() * 1000);
}
BENCHMARK(BM_VmcPublish);

}  // namespace

BENCHMARK_MAIN();
