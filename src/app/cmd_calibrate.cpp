// hotgauge calibrate: the cell's geometry into calibration.yaml (docs/calibration.md).
//   nominal  the design values a cell config asserts, as method `nominal`: what a cell runs on
//            before it is commissioned; the daemon says so at start.
#include <spdlog/spdlog.h>

#include <memory>

#include "commands.hpp"
#include "hotgauge/calib/calibration.hpp"
#include "hotgauge/core/clock.hpp"
#include "hotgauge/sim/simulator.hpp"
#include "hotgauge/vcell/render.hpp"

namespace hotgauge::app {
namespace {

struct CalibrateArgs {
    std::string cell = HOTGAUGE_CONFIG_DIR "/cell.yaml";
    std::string out;
};

int run_nominal(const CalibrateArgs& a) {
    auto cell = sim::read_cell_config(a.cell);
    if (!cell) {
        spdlog::error("{}", cell.error().message);
        return 1;
    }
    const auto c =
        vcell::nominal_calibration(*cell, a.cell, core::iso8601_utc(core::realtime_ns()));
    if (auto w = calib::write_calibration(c, a.out); !w) {
        spdlog::error("{}", w.error().message);
        return 1;
    }
    spdlog::info("{}: nominal geometry of {} ({} faces): design values, not measured", a.out,
                 a.cell, c.faces.size());
    return 0;
}

}  // namespace

Command add_calibrate(CLI::App& app) {
    auto a = std::make_shared<CalibrateArgs>();
    auto* s = app.add_subcommand("calibrate", "the cell's geometry (docs/calibration.md)");
    s->require_subcommand(1);
    auto* nominal =
        s->add_subcommand("nominal", "a cell config's design geometry as calibration.yaml");
    nominal->add_option("--cell", a->cell, "cell config")->capture_default_str();
    nominal->add_option("--out,-o", a->out, "calibration file to write")->required();
    return [a] { return run_nominal(*a); };
}

}  // namespace hotgauge::app
