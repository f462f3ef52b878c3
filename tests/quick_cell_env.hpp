#pragma once
// Test helper: hub-a on the quick cell with the real accelerometer (2 kHz, 25 µg/√Hz), and a part
// simulated on it at 1000 °C: the compensation's and the pipeline's tests (test_compensate,
// test_pipeline) measure the same parts.
#include <cstdint>
#include <cstdlib>
#include <utility>

#include "hotgauge/io/recipe.hpp"
#include "hotgauge/sim/simulator.hpp"

namespace hotgauge::test {

struct QuickCellEnv {
    core::Recipe recipe;
    sim::CellConfig cell;  // quick sensor, but the real accelerometer (2 kHz, 25 µg/√Hz)
};

inline const QuickCellEnv& env() {
    static const QuickCellEnv e = [] {
        auto r = io::read_recipe(HOTGAUGE_SOURCE_DIR "/config/parts/hub-a.yaml");
        auto c = sim::read_cell_config(HOTGAUGE_SOURCE_DIR "/config/cell.yaml");
        if (!r || !c) std::abort();
        sim::CellConfig q = sim::quick(*c);
        q.accel = c->accel;
        return QuickCellEnv{*r, q};
    }();
    return e;
}

inline sim::SimResult simulate(const sim::CellConfig& cell, std::uint64_t seed,
                               bool forged = false) {
    sim::SimOptions o;
    o.seed = seed;
    o.forged = forged;
    o.temperature_c = 1000.0;
    o.t0_ns = 1'790'000'000'000'000'000;
    auto s = sim::simulate(env().recipe, cell, o);
    if (!s) std::abort();
    return std::move(*s);
}

}  // namespace hotgauge::test
