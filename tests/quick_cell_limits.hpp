#pragma once
// The face alignment's σ limits for the coarse test cell (sim::quick: W/4 rays, 1 mm profiles,
// 25 times fewer points than the real sensor), which fixes a face about five times less well:
// five times docs/calibration.md's.
#include "hotgauge/calib/align.hpp"

namespace hotgauge::test {

inline calib::AlignLimits quick_cell_limits() {
    calib::AlignLimits l;
    l.max_sigma_position_mm *= 5.0;
    l.max_sigma_rotation_deg *= 5.0;
    l.max_sigma_travel_ppm *= 5.0;
    l.max_sigma_direction_deg *= 5.0;
    return l;
}

}  // namespace hotgauge::test
