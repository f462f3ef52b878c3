#pragma once
// The part report (docs/results.md "Part report"): one self-contained HTML page per part for the
// quality engineer. Per face the range image and the deviation map of the compensated scan from
// the nominal hot surface, with the measured levels and edge circles drawn over it; the feature
// table with each value on its tolerance band.
#include <Eigen/Geometry>
#include <cstdint>
#include <string>
#include <vector>

#include "hotgauge/core/part.hpp"
#include "hotgauge/core/recording.hpp"
#include "hotgauge/core/result.hpp"
#include "hotgauge/pipeline/pipeline.hpp"

namespace hotgauge::report {

struct PartReportConfig {
    // A point farther than this from the nominal surface is not the part (a fixture, a spike):
    // drawn grey, off the colour scale. So is the support plate the part stands on.
    double off_part_mm = 3.0;
    double support_band_mm = 0.5;  // the support: this close to the part's lowest level
    // Overlays: pixels within this of a measured level (a height's end) or of a measured edge
    // circle (a diameter's edge, in the (r, z) half-plane).
    double level_band_mm = 0.3;
    double edge_band_mm = 1.0;
};

enum class PixelKind : std::uint8_t { kNoPoint, kOffPart, kPart };

// One face's compensated scan against the nominal surface, per pixel of its range image (profile
// k, column i at k·width + i).
struct DeviationMap {
    std::string face;
    std::int64_t profiles = 0, width = 0;
    std::vector<PixelKind> kind;
    // Signed distance from the nominal hot surface, mm: + outside the material (excess, flash),
    // − inside (underfill). NaN unless kPart.
    std::vector<float> deviation_mm;
    // The point in the hot part frame: distance from the axis and height, mm. NaN: no point.
    std::vector<float> r_mm, z_mm;
};

// The scale of the nominal surface a hot scan is compared with: the result's thermal growth,
// or, without a temperature, the scale the matching estimated (1 when neither is known).
double hot_scale(const pipeline::PartResult& result);

// Each valid point of `face`, moved by its profile's compensation displacement `displacement_mm`
// (one per profile, or none), taken to the part frame with `T_world_part` and compared with
// `nominal_hot` (core::AxisymmetricSolid::from_recipe(recipe, {}, {}, hot_scale(result))).
DeviationMap deviation_map(const core::FaceScan& face,
                           const std::vector<Eigen::Vector3d>* displacement_mm,
                           const Eigen::Isometry3d& T_world_part,
                           const core::AxisymmetricSolid& nominal_hot,
                           const PartReportConfig& config = {});

// A face's range image (the page's first picture, grey by range) from every step-th profile and
// column, the whole step that makes it at most `max_side_px` on its longer side, as a PNG file's
// bytes: the daemon's status page (web). A face without profiles or columns: no bytes.
struct FacePicture {
    std::string face;
    int width = 0, height = 0;  // of the PNG
    std::vector<std::uint8_t> png;
};
FacePicture range_png(const core::FaceScan& face, int max_side_px = 512);

// The page: `result` is pipeline::run's on `rec` with `recipe`. A result without a pose (part not
// found) gets the range images and the table, no deviation maps. Errors: a face of the result
// missing from the recording, or a face whose compensation does not have one displacement per
// profile (the result is of another recording).
core::Result<std::string> part_report_html(const core::Recording& rec, const core::Recipe& recipe,
                                           const pipeline::PartResult& result,
                                           const PartReportConfig& config = {});

}  // namespace hotgauge::report
