// filter_bench — cost of one update() per filter on the realistic scenario (100 Hz, 9-axis),
// and of the offline re-solve (OfflineSmoother with the default filter) per sample.
//
// A buffer of samples is generated once and cycled through, timestamps shifted on each
// pass so the filters never see a gap; the offline re-solve takes the whole buffer per
// iteration and counts its samples as items, so its items/s reads as a cost per sample. docs/performance.md records the
// numbers and the command. Not a ctest test (timing on a shared machine); a smoke run keeps it working.
#include <benchmark/benchmark.h>

#include <memory>
#include <vector>

#include "filter/csmo.hpp"
#include "filter/madgwick.hpp"
#include "filter/mahony.hpp"
#include "filter/mocap_filter.hpp"
#include "filter/offline_smoother.hpp"
#include "filter/particle_filter.hpp"
#include "sim/scenario.hpp"

namespace {

using namespace mocap;
using namespace mocap::filter;

const std::vector<ImuSample>& samples() {
    static const std::vector<ImuSample> s = [] {
        const sim::Scenario sc = sim::make_scenario(sim::ScenarioKind::realistic, 1);
        std::vector<ImuSample> out;
        out.reserve(sc.rows.size());
        for (const sim::ScenarioRow& r : sc.rows)
            out.push_back(r.sample);
        return out;
    }();
    return s;
}

void run(benchmark::State& state, OrientationFilter& f) {
    const std::vector<ImuSample>& buf = samples();
    const std::int64_t period_us = buf.back().t_us - buf.front().t_us + 10000;
    // Warm up past the start (initialisation, filter start-up averaging).
    for (std::size_t i = 0; i < 1000; ++i)
        f.update(buf[i]);
    std::size_t i = 1000;
    std::int64_t offset_us = 0;
    for (auto _ : state) {
        ImuSample s = buf[i];
        s.t_us += offset_us;
        f.update(s);
        if (++i == buf.size()) {
            i = 0;
            offset_us += period_us;
        }
        benchmark::DoNotOptimize(f.orientation());
    }
    state.SetItemsProcessed(state.iterations());
}

template <class Filter>
void BM_Update(benchmark::State& state) {
    Filter f;
    run(state, f);
}

void BM_ParticleFilter(benchmark::State& state) {
    ParticleFilterParams p;
    p.particles = static_cast<int>(state.range(0));
    ParticleFilter f(p);
    run(state, f);
}

void BM_OfflineSmoother(benchmark::State& state) {
    const std::vector<ImuSample>& buf = samples();
    MocapFilter f;
    const OfflineSmoother smoother;
    for (auto _ : state) {
        const OfflineResult r = smoother.smooth(f, buf);
        benchmark::DoNotOptimize(r.orientation.data());
    }
    state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(buf.size()));
}

BENCHMARK_TEMPLATE(BM_Update, MadgwickFilter);
BENCHMARK_TEMPLATE(BM_Update, MahonyFilter);
BENCHMARK_TEMPLATE(BM_Update, MocapFilter);
BENCHMARK_TEMPLATE(BM_Update, Csmo);
BENCHMARK(BM_ParticleFilter)->Arg(64)->Arg(256)->Arg(1024);
BENCHMARK(BM_OfflineSmoother)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
