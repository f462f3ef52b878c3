// Benchmarks on fixed simulated data (docs/benchmarks.md): run `make bench`.
#include <benchmark/benchmark.h>

#include <cstdio>

#include "hotgauge/compensate/compensate.hpp"
#include "hotgauge/io/recipe.hpp"
#include "hotgauge/measure/features.hpp"
#include "hotgauge/sim/simulator.hpp"

using namespace hotgauge;

namespace {

struct Scene {
    core::Recipe recipe;
    sim::SimResult sim;
};

// One full-resolution four-face hub-a part (2048 points per profile, 0.2 mm profiles), seed 1,
// 1050 °C, no vibration: the data every measure benchmark runs on.
const Scene& scene() {
    static const Scene s = [] {
        auto r = io::read_recipe(HOTGAUGE_SOURCE_DIR "/config/parts/hub-a.yaml");
        auto c = sim::read_cell_config(HOTGAUGE_SOURCE_DIR "/config/cell.yaml");
        if (!r || !c) std::abort();
        c->vibration.enabled = false;
        sim::SimOptions o;
        o.seed = 1;
        o.temperature_c = 1050.0;
        o.t0_ns = 1'790'000'000'000'000'000;
        auto sim = sim::simulate(*r, *c, o);
        if (!sim) std::abort();
        std::int64_t points = 0;
        for (const auto& f : sim->recording.faces)
            for (std::size_t q = 0; q < f.profiles_mm.size(); q += 2)
                points += f.profiles_mm[q] == f.profiles_mm[q];
        std::printf("scene: hub-a, 4 faces, %lld valid points, 1050 °C, seed 1\n",
                    static_cast<long long>(points));
        return Scene{*r, std::move(*sim)};
    }();
    return s;
}

void BM_MeasurePart4Faces(benchmark::State& state) {
    const Scene& s = scene();
    for (auto _ : state) {
        auto m = measure::measure_part(s.recipe, s.sim.recording, s.sim.truth.T_world_part);
        benchmark::DoNotOptimize(m);
    }
    state.SetLabel("13 features, truth pose");
}
BENCHMARK(BM_MeasurePart4Faces)->Unit(benchmark::kMillisecond)->MinTime(2.0);

// The same on one core, as `hotgauge remeasure` measures each part (issue 42: <= 120 ms).
void BM_MeasurePart4FacesOneCore(benchmark::State& state) {
    const Scene& s = scene();
    measure::MeasureConfig one;
    one.threads = 1;
    for (auto _ : state) {
        auto m =
            measure::measure_part(s.recipe, s.sim.recording, s.sim.truth.T_world_part, {}, one);
        benchmark::DoNotOptimize(m);
    }
    state.SetLabel("13 features, truth pose, threads 1");
}
BENCHMARK(BM_MeasurePart4FacesOneCore)->Unit(benchmark::kMillisecond)->MinTime(2.0);

}  // namespace

namespace {
// The shared preparation alone (part-frame grid, ray model per column): a recipe with no features.
void BM_MeasurePrepareOnly(benchmark::State& state) {
    const Scene& s = scene();
    core::Recipe empty = s.recipe;
    empty.features.clear();
    for (auto _ : state) {
        auto m = measure::measure_part(empty, s.sim.recording, s.sim.truth.T_world_part);
        benchmark::DoNotOptimize(m);
    }
}
BENCHMARK(BM_MeasurePrepareOnly)->Unit(benchmark::kMillisecond)->MinTime(1.0);
}  // namespace

namespace {
// Vibration compensation of all four faces (each: 3-axis record of the scan + 2 s margins at
// 2 kHz, three FFT double integrations, interpolation at 1201 profile times).
void BM_Compensate4Faces(benchmark::State& state) {
    const Scene& s = scene();
    for (auto _ : state)
        for (const auto& f : s.sim.recording.faces) {
            auto c = compensate::compensate_face(f, {});
            benchmark::DoNotOptimize(c);
        }
}
BENCHMARK(BM_Compensate4Faces)->Unit(benchmark::kMillisecond)->MinTime(1.0);
}  // namespace

BENCHMARK_MAIN();
