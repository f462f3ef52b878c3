#pragma once
// The part report's pictures (docs/results.md "Part report"): the range image, the deviation map
// coloured on a diverging scale, and the measured levels and edge circles drawn over it.
#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "hotgauge/core/recording.hpp"
#include "hotgauge/report/html.hpp"
#include "hotgauge/report/part_report.hpp"

namespace hotgauge::report {

using Colour = std::array<std::uint8_t, 3>;
std::string hex(const Colour& c);  // "#rrggbb", for SVG and CSS

inline constexpr Colour kNoPointColour{0, 0, 0};
inline constexpr Colour kOffPartColour{136, 136, 136};
inline constexpr Colour kLevelColour{0, 200, 0};
inline constexpr Colour kEdgeColour{255, 224, 0};

// The diverging scale (ColorBrewer RdBu, 11 classes, blue = underfill, white = nominal, red =
// excess), from −scale_mm to +scale_mm, saturating beyond.
const std::vector<Colour>& deviation_stops();
Colour deviation_colour(double deviation_mm, double scale_mm);

// Grey by range (near white, far dark grey) between the 1st and 99th percentile of the face's
// ranges, so that one stray return does not flatten the picture; no return black.
struct RangePicture {
    RgbImage image;
    double near_mm = 0, far_mm = 0;  // the ranges drawn white and darkest
};
// `step` > 1: every step-th profile and column only, a picture step times smaller each way
// (percentiles from those points): the status page's, at a fraction of the cost.
RangePicture range_picture(const core::FaceScan& face, int step = 1);

// A measured level or edge circle of the hot part frame, to draw over a face's deviation map.
struct Overlay {
    std::string features;       // "Height 1, Height 2": the features it is an end or edge of
    std::string level;          // the recipe's level: "spigot_end"
    std::string what;           // "spigot_end (plane)", "boss_top edge (convex corner)"
    bool edge_circle = false;   // an edge circle of radius r_mm at height z_mm; else the level z_mm
    double r_mm = 0, z_mm = 0;  // hot part frame
};

// The pixels of the map's part within the overlay's band (config), as the region's outline (a
// plane's whole face would hide its deviations; holes without a point make none), and the
// region pixel farthest from the region's centre in the picture's direction `label_rad`, for its
// label: so that the labels of concentric rings and parallel lines spread out. No region: both
// empty.
struct OverlayPixels {
    std::vector<std::int64_t> outline;
    std::optional<std::int64_t> anchor;
};
OverlayPixels overlay_pixels(const DeviationMap& map, const Overlay& overlay,
                             const PartReportConfig& config, double label_rad);

// The map coloured by deviation (no point black, off the part grey), the overlays' outlines
// drawn over it in their colours.
RgbImage deviation_picture(const DeviationMap& map, double scale_mm,
                           const std::vector<Overlay>& overlays,
                           const std::vector<OverlayPixels>& pixels);

}  // namespace hotgauge::report
