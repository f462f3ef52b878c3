#pragma once
// The commissioning report (docs/calibration.md "Commissioning report"): one self-contained HTML
// page an integrator signs after `hotgauge calibrate faces --report DIR`, accepted or refused.
#include <string>

#include "hotgauge/calib/align.hpp"

namespace hotgauge::report {

// Per face: the balls and planes seen with their residual RMS and mean, the σ table against the
// limits, the residual map over the scan, the geometry before and after; the verdict and, when
// refused, why. `recording` and `artifact_file` are named on the page as given.
std::string commissioning_html(const calib::Commissioning& result, const std::string& recording,
                               const std::string& artifact_file);

}  // namespace hotgauge::report
