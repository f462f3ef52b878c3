#pragma once
// Subcommands of the engineer's tool `hotgauge`. Each registers itself on the CLI11 app and
// returns the process exit code when run.
#include <CLI/CLI.hpp>
#include <functional>
#include <optional>
#include <string>

#include "hotgauge/core/recording.hpp"
#include "hotgauge/pipeline/pipeline.hpp"

namespace hotgauge::app {

using Command = std::function<int()>;

Command add_simulate(CLI::App& app);
Command add_measure(CLI::App& app);
Command add_table1(CLI::App& app);
Command add_fit(CLI::App& app);
Command add_model(CLI::App& app);
Command add_grab(CLI::App& app);
Command add_plc(CLI::App& app);
Command add_calibrate(CLI::App& app);
Command add_verify(CLI::App& app);
Command add_study(CLI::App& app);
// `hotgauge report` and its subcommands (docs/results.md): `report part` is add_report_part.
Command add_report(CLI::App& app);
Command add_report_part(CLI::App* report);
Command add_export(CLI::App& app);
Command add_remeasure(CLI::App& app);

// The shipped recipe of part `part` (config/parts/<part>.yaml): the recipe a recording is
// measured with when none is given (`measure`, `verify`, `remeasure`).
inline std::string shipped_recipe(const std::string& part) {
    return std::string(HOTGAUGE_CONFIG_DIR "/parts/") + part + ".yaml";
}

// The measure job, shared by `measure` and `verify`: read the recording, take the calibration's
// geometry, read the recipe, the pose or model, run the pipeline.
struct MeasureJob {
    std::string recording;
    std::string recipe;          // default: config/parts/<recording's recipe>.yaml
    std::string pose = "match";  // match | truth
    std::string part_pose;       // a pose file: no matching
    std::string model;           // a saved model (hotgauge model build); default: from the recipe
    std::string calibration;     // the cell's geometry in place of the recording's face.yaml
    bool no_compensation = false;
    double clock_offset_ms = 0.0;
    double highpass_hz = 0.0;
    int threads = 0;  // matching and measurement (0: one per core); the numbers do not change
    std::optional<double> default_temperature_c;  // when the recording has none (a cold master)
};
void add_measure_job_options(CLI::App* command, MeasureJob& job);
// Logs what went wrong and returns nullopt; `recording` and `recipe` (optional) get the
// recording measured and the recipe it was measured with.
std::optional<pipeline::PartResult> measure_job(const MeasureJob& job,
                                                core::Recording* recording = nullptr,
                                                core::Recipe* recipe = nullptr);

}  // namespace hotgauge::app
