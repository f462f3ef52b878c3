#pragma once
// The feature kinds of a recipe, each measured on the prepared faces (docs/measurement.md):
// diameters from edge circles, heights from planes or from edges along the axis. Internal to the
// measure module; `measure_part` (features.cpp) dispatches to these.
#include <vector>

#include "frame.hpp"
#include "hotgauge/core/part.hpp"
#include "hotgauge/measure/features.hpp"
#include "surfaces.hpp"

namespace hotgauge::measure::detail {

struct CornerMemo;  // corner.hpp

// Diameter of the circular edge where `f.section`'s wall meets the level `f.edge_at`. `memo`: a
// forging's corner as the faces that see its plane gave it, kept between calls (or nullptr).
void measure_diameter(const Context& ctx, const core::FeatureSpec& f,
                      const std::vector<const FaceFrame*>& frames, FeatureResult& r,
                      CornerMemo* memo = nullptr);

// Whether `frame` sees the plane of a diameter's edge (else, on a forging, only its wall).
bool sees_edge_plane(const Context& ctx, const core::FeatureSpec& f, const FaceFrame& frame);

// Height between two levels, each end by the best estimator its faces allow (planes where the
// level's face is seen, corners and silhouette edges where it is not).
void measure_height(const Context& ctx, const core::FeatureSpec& f,
                    const std::vector<const FaceFrame*>& frames, FeatureResult& r);

// Die shift: the distance between the axes of the part's halves, from the centres of the
// measured diameters' circles above and below the parting plane (forged.cpp).
void measure_die_shift(const Context& ctx, const std::vector<FeatureResult>& measured,
                       FeatureResult& r);

// Closes a feature's uncertainty budget: the sector spread's standard error joins the terms
// (docs/measurement.md, "Uncertainty"), and u_mm becomes their quadrature sum.
void add_sector_term(FeatureResult& r);

}  // namespace hotgauge::measure::detail
