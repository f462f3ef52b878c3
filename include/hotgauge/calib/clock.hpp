#pragma once
// The camera → accelerometer clock offset from a scan of the artifact while the press runs
// (docs/calibration.md "Clock offset"): the artifact's surfaces (its spheres and the support
// plate) appear to move with the head; the compensated points lie on them only when the
// accelerometer's displacement is taken at the right time. The offset whose compensation fits
// them best is the clock offset. Each profile weighs the same (its points share one
// displacement); a coarse search on every point near the artifact, then a fine one on the points
// that lie on it once compensated (spikes and reflections out).
#include "hotgauge/calib/artifact.hpp"
#include "hotgauge/compensate/compensate.hpp"
#include "hotgauge/core/recording.hpp"
#include "hotgauge/core/result.hpp"

namespace hotgauge::calib {

struct ClockOffset {
    std::int64_t offset_ns = 0;  // total: what the camera's timestamps need added
    // Standard uncertainty: the scatter of the offsets found on blocks of a third of a face
    // (a conservative figure: the virtual cell's errors are below it).
    double u_ns = 0.0;
    double residual_mm = 0.0;  // point-to-surface RMS after compensation at offset_ns
    double motion_mm = 0.0;    // RMS of the apparent displacement per profile: how much it moved
    int profiles = 0;          // profiles used, all faces
};

// `recording` must carry the calibrated geometry (calib::apply_geometry) and have the press
// running (the points must move at least 20 µm RMS). The search covers ±search_ms around the
// recording's own offset; an offset at its edge is refused.
core::Result<ClockOffset> estimate_clock_offset(const core::Recording& recording,
                                                const Artifact& artifact,
                                                const compensate::CompensationConfig& config = {},
                                                double search_ms = 5.0);

}  // namespace hotgauge::calib
