#pragma once
// The simulated cell's geometry as a calibration (docs/calibration.md, "The virtual cell"): what
// a cell config asserts (nominal), a seeded true geometry that differs from it as a real cell's
// does, and a cell config that renders at a calibration's geometry. The simulator reads the
// truth from a calibration file; the software under test reads the calibration in force.
#include <cstdint>
#include <string>

#include "hotgauge/calib/calibration.hpp"
#include "hotgauge/core/result.hpp"
#include "hotgauge/sim/simulator.hpp"

namespace hotgauge::sim {

// The sensor of a cell config as the calibration's direct-beam model.
calib::SensorModel sensor_model(const SensorConfig& sensor);

// The geometry a cell config asserts, as a calibration of method `nominal` (design values, not
// measured): what a cell runs on before it is commissioned. `source` names the config file.
calib::Calibration nominal_calibration(const CellConfig& cell, const std::string& source,
                                       const std::string& calibrated_at);

// How far a real cell's geometry is from its drawings (issue 16's commissioning rehearsal).
struct Perturbation {
    double translation_mm = 2.0;    // each face's camera position, |Δ| uniform in a ball
    double rotation_deg = 0.5;      // each face's camera orientation, about a random axis
    double direction_deg = 0.1;     // each face's scan direction
    double accel_mount_deg = 5.0;   // the accelerometer's mount in the head (one head)
    double clock_offset_ms = 2.0;   // camera → accelerometer clock, uniform in ±this
    double travel_scale = 0.002;    // axis speed / encoder error, uniform in ±this
    double accel_bias_mps2 = 0.01;  // per axis, uniform in ±this
};

// `nominal` moved by amounts drawn from `seed` within `limits`: method `virtual-truth`.
calib::Calibration perturbed_calibration(const calib::Calibration& nominal, std::uint64_t seed,
                                         const Perturbation& limits = {});

// `cell` rendering at `truth`'s geometry: every face's pose, scan direction, travel scale and
// accelerometer mount, the clock offset and a fixed accelerometer bias. Every face of the cell
// must be in `truth` (the error names `truth_file` and the face); the sensor model must agree.
core::Result<CellConfig> with_geometry(CellConfig cell, const calib::Calibration& truth,
                                       const std::string& truth_file);

}  // namespace hotgauge::sim
