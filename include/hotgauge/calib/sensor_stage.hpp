#pragma once
// The sensor calibrated as profile heads are calibrated by their makers (docs/calibration.md
// "Sensor on a stage"): a flat plate of certified flatness moved by a precision stage to known
// heights, level and tilted, across the measuring range, imaged with only the laser line on it.
// Each image column's range law is fitted to the level plate's known heights, its x law to where
// the tilted plates put the line; no corners, no camera model: the pixel → mm map directly, in
// the acquisition's calibrated triangulation model.
#include <filesystem>
#include <vector>

#include "hotgauge/acquire/triangulation.hpp"
#include "hotgauge/calib/sensor.hpp"
#include "hotgauge/core/result.hpp"

namespace hotgauge::calib {

// One stage position. The stage's frame is the sensor's laser frame (x along the line, z the
// range): the plate crosses the laser plane in the line z = height_mm + tan(tilt)·x (the stage
// tilts it about the laser plane's normal through x = 0).
struct StageReading {
    GrayImage laser;         // only the laser line on the plate
    double height_mm = 0.0;  // where the plate crosses x = 0
    double tilt_deg = 0.0;   // 0: level
};

struct StageFit {
    acquire::CalibratedModel model;
    double rms_z_mm = 0.0;  // level plates: the law's z against the stage's heights
    double rms_x_mm = 0.0;  // tilted plates: the law's x against where the plate puts the line
    int samples = 0;        // stripe points used
    int readings = 0;
};

// Refused by name: fewer than degree + 2 level readings or x_degree + 1 tilted ones (each column
// needs that many), a reading without a laser line, a tilt of 60° or more.
core::Result<StageFit> calibrate_sensor_stage(const std::vector<StageReading>& readings,
                                              int degree = 3, int x_degree = 3);

// The stage file (docs/calibration.md "Sensor on a stage"): format hotgauge-sensor-stage-1 and
// `readings`, a list of {laser: PNG, height_mm, tilt_deg} (8-bit grey, paths relative to the
// file). Errors name file:line and the key, or the image.
core::Result<std::vector<StageReading>> read_sensor_stage(const std::filesystem::path& file);
// Writes the images as DIR/stageNN.png and DIR/stage.yaml.
core::Result<void> write_sensor_stage(const std::vector<StageReading>& readings,
                                      const std::filesystem::path& dir);

}  // namespace hotgauge::calib
