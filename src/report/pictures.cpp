#include "pictures.hpp"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstdio>
#include <limits>

#include "hotgauge/core/geometry.hpp"
#include "hotgauge/core/parallel.hpp"

namespace hotgauge::report {
namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// The part's lowest level, where it stands on the support plate (the part frame's origin is on
// the axis at the lowest face, docs/architecture.md "Frames").
double lowest_z(const core::AxisymmetricSolid& solid) {
    double z = std::numeric_limits<double>::max();
    for (const auto& s : solid.boundary()) z = std::min(z, s.cylinder ? s.lo : s.value);
    return z;
}

std::uint8_t lerp(std::uint8_t a, std::uint8_t b, double t) {
    return static_cast<std::uint8_t>(std::lround(a + (b - a) * t));
}

}  // namespace

double hot_scale(const pipeline::PartResult& result) {
    if (result.measurement.growth) return *result.measurement.growth;
    if (result.match && result.match->found) return result.match->scale;
    return 1.0;
}

DeviationMap deviation_map(const core::FaceScan& face,
                           const std::vector<Eigen::Vector3d>* displacement_mm,
                           const Eigen::Isometry3d& T_world_part,
                           const core::AxisymmetricSolid& nominal_hot,
                           const PartReportConfig& config) {
    DeviationMap m;
    m.face = face.name;
    m.profiles = face.n_profiles();
    m.width = face.width;
    const auto n = static_cast<std::size_t>(m.profiles * m.width);
    m.kind.assign(n, PixelKind::kNoPoint);
    m.deviation_mm.assign(n, kNaN);
    m.r_mm.assign(n, kNaN);
    m.z_mm.assign(n, kNaN);
    const core::FaceCloud cloud = core::world_cloud(face, displacement_mm);
    const Eigen::Isometry3d T_part_world = T_world_part.inverse();
    const double z_floor = lowest_z(nominal_hot), band = config.support_band_mm;
    // Each point is independent: chunks over the cores, each writing its own pixels.
    constexpr std::size_t kChunk = 8192;
    const std::size_t points = cloud.points_mm.size();
    core::parallel_for((points + kChunk - 1) / kChunk, 0, [&](std::size_t chunk, unsigned) {
        for (std::size_t j = chunk * kChunk; j < std::min(points, (chunk + 1) * kChunk); ++j) {
            const Eigen::Vector3d p = T_part_world * cloud.points_mm[j];
            const double r = std::hypot(p.x(), p.y()), z = p.z();
            const auto px = static_cast<std::size_t>(cloud.profile[j] * m.width + cloud.column[j]);
            m.r_mm[px] = static_cast<float>(r);
            m.z_mm[px] = static_cast<float>(z);
            const double d = nominal_hot.distance(p);
            // The support plate: at the lowest level, with no material just above it (around
            // the part, and inside a bore that goes through).
            const bool support =
                std::abs(z - z_floor) < band && !nominal_hot.inside(r, z_floor + band);
            if (support || d > config.off_part_mm) {
                m.kind[px] = PixelKind::kOffPart;
                continue;
            }
            m.kind[px] = PixelKind::kPart;
            m.deviation_mm[px] = static_cast<float>(nominal_hot.inside(r, z) ? -d : d);
        }
    });
    return m;
}

std::string hex(const Colour& c) {
    char b[8];
    std::snprintf(b, sizeof b, "#%02x%02x%02x", c[0], c[1], c[2]);
    return b;
}

const std::vector<Colour>& deviation_stops() {
    static const std::vector<Colour> stops = {{5, 48, 97},     {33, 102, 172},  {67, 147, 195},
                                              {146, 197, 222}, {209, 229, 240}, {247, 247, 247},
                                              {253, 219, 199}, {244, 165, 130}, {214, 96, 77},
                                              {178, 24, 43},   {103, 0, 31}};
    return stops;
}

Colour deviation_colour(double deviation_mm, double scale_mm) {
    const auto& stops = deviation_stops();
    const double t = std::clamp(0.5 + 0.5 * deviation_mm / scale_mm, 0.0, 1.0) *
                     static_cast<double>(stops.size() - 1);
    const auto i = std::min(static_cast<std::size_t>(t), stops.size() - 2);
    const double f = t - static_cast<double>(i);
    const Colour &a = stops[i], &b = stops[i + 1];
    return {lerp(a[0], b[0], f), lerp(a[1], b[1], f), lerp(a[2], b[2], f)};
}

RangePicture range_picture(const core::FaceScan& face, int step) {
    assert(step >= 1);
    const auto n = static_cast<int>(face.n_profiles()), w = static_cast<int>(face.width);
    RangePicture out{RgbImage((w + step - 1) / step, (n + step - 1) / step), 0, 0};
    std::vector<float> ranges;
    for (int k = 0; k < n; k += step)
        for (int i = 0; i < w; i += step)
            if (!std::isnan(face.x(k, i)) && !std::isnan(face.z(k, i)))
                ranges.push_back(face.z(k, i));
    if (ranges.empty()) return out;
    auto percentile = [&](double q) {
        auto at = ranges.begin() +
                  static_cast<std::ptrdiff_t>(q * static_cast<double>(ranges.size() - 1));
        std::nth_element(ranges.begin(), at, ranges.end());
        return static_cast<double>(*at);
    };
    out.near_mm = percentile(0.01);
    out.far_mm = std::max(percentile(0.99), out.near_mm + 1e-3);
    for (int k = 0; k < n; k += step)
        for (int i = 0; i < w; i += step) {
            if (std::isnan(face.x(k, i)) || std::isnan(face.z(k, i))) continue;
            const double t =
                std::clamp((face.z(k, i) - out.near_mm) / (out.far_mm - out.near_mm), 0.0, 1.0);
            const auto g = static_cast<std::uint8_t>(std::lround(255.0 - 195.0 * t));
            out.image.set(i / step, k / step, {g, g, g});
        }
    return out;
}

FacePicture range_png(const core::FaceScan& face, int max_side_px) {
    FacePicture out{face.name, 0, 0, {}};
    if (face.n_profiles() == 0 || face.width == 0) return out;
    const auto longer = static_cast<int>(
        std::max<std::int64_t>(face.width, static_cast<std::int64_t>(face.n_profiles())));
    const int step = std::max(1, (longer + max_side_px - 1) / std::max(1, max_side_px));
    const RgbImage image = range_picture(face, step).image;
    out.width = image.width;
    out.height = image.height;
    out.png = png_bytes(image);
    return out;
}

OverlayPixels overlay_pixels(const DeviationMap& m, const Overlay& o, const PartReportConfig& c,
                             double label_rad) {
    const auto n = static_cast<std::size_t>(m.profiles * m.width);
    std::vector<std::uint8_t> in(n, 0);
    double sum_k = 0, sum_i = 0, count = 0;
    for (std::size_t px = 0; px < n; ++px) {
        if (m.kind[px] != PixelKind::kPart) continue;
        const double dz = m.z_mm[px] - o.z_mm;
        const bool near = o.edge_circle ? std::hypot(m.r_mm[px] - o.r_mm, dz) < c.edge_band_mm
                                        : std::abs(dz) < c.level_band_mm;
        if (!near) continue;
        in[px] = 1;
        sum_k += static_cast<double>(px / m.width);
        sum_i += static_cast<double>(px % m.width);
        ++count;
    }
    OverlayPixels out;
    if (count == 0) return out;
    const double ck = sum_k / count, ci = sum_i / count;
    const double dk = std::sin(label_rad), di = std::cos(label_rad);
    double best = -std::numeric_limits<double>::max();
    const auto w = static_cast<std::size_t>(m.width), rows = static_cast<std::size_t>(m.profiles);
    // A neighbour with a point that is not in the region: the region ends there.
    auto outside = [&](std::size_t q) { return !in[q] && m.kind[q] != PixelKind::kNoPoint; };
    for (std::size_t px = 0; px < n; ++px) {
        if (!in[px]) continue;
        const std::size_t k = px / w, i = px % w;
        if ((k > 0 && outside(px - w)) || (k + 1 < rows && outside(px + w)) ||
            (i > 0 && outside(px - 1)) || (i + 1 < w && outside(px + 1)))
            out.outline.push_back(static_cast<std::int64_t>(px));
        const double along =
            (static_cast<double>(k) - ck) * dk + (static_cast<double>(i) - ci) * di;
        if (along > best) best = along, out.anchor = static_cast<std::int64_t>(px);
    }
    return out;
}

RgbImage deviation_picture(const DeviationMap& m, double scale_mm,
                           const std::vector<Overlay>& overlays,
                           const std::vector<OverlayPixels>& pixels) {
    const auto w = static_cast<int>(m.width), n = static_cast<int>(m.profiles);
    RgbImage image(w, n);
    for (int k = 0; k < n; ++k)
        for (int i = 0; i < w; ++i) {
            const std::size_t px = static_cast<std::size_t>(k) * m.width + i;
            switch (m.kind[px]) {
                case PixelKind::kNoPoint:
                    image.set(i, k, kNoPointColour);
                    break;
                case PixelKind::kOffPart:
                    image.set(i, k, kOffPartColour);
                    break;
                case PixelKind::kPart:
                    image.set(i, k, deviation_colour(m.deviation_mm[px], scale_mm));
                    break;
            }
        }
    for (std::size_t j = 0; j < overlays.size(); ++j)
        for (const std::int64_t px : pixels[j].outline)
            image.set(static_cast<int>(px % m.width), static_cast<int>(px / m.width),
                      overlays[j].edge_circle ? kEdgeColour : kLevelColour);
    return image;
}

}  // namespace hotgauge::report
