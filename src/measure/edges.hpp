#pragma once
// Edges on the scan grid (docs/measurement.md, "Edges and circles"): where rays cross fitted
// surfaces, the brackets two neighbouring rays put around an edge, and the estimators that turn
// brackets into an edge (interval stabbing, the bracket circle). Internal to the measure module.
#include <Eigen/Geometry>
#include <optional>
#include <utility>
#include <vector>

#include "frame.hpp"
#include "hotgauge/measure/fit.hpp"

namespace hotgauge::measure::detail {

// Where the ray o + s·d crosses the plane; s is the camera range (NaN if parallel).
double cross_plane(const PlaneFit& pl, const Eigen::Vector3d& o, const Eigen::Vector3d& d);
// Nearest crossing of the ray with the cylinder r = radius about the part axis (NaN if none).
double cross_cylinder(double radius, const Eigen::Vector3d& o, const Eigen::Vector3d& d);

// Local normal from the scan grid neighbourhood (±2 profiles × ±2 columns).
std::optional<Eigen::Vector3d> grid_normal(const FaceFrame& fr, std::int64_t k, std::int64_t i);
// Many samples of one face against a plane, each sample's distance computed once and kept (a
// sample falls in 25 of its neighbours' 5×5 neighbourhoods). The samples asked about lie in
// profiles [k_lo, k_hi] and columns [i_lo, i_hi]; their neighbourhoods may reach 2 beyond.
class PlaneSides {
  public:
    PlaneSides(const FaceFrame& fr, const PlaneFit& plane, double thr, std::int64_t k_lo,
               std::int64_t k_hi, std::int64_t i_lo, std::int64_t i_hi);
    // Every valid sample of the 5×5 grid neighbourhood within thr of the plane.
    bool flat_around(std::int64_t k, std::int64_t i);
    // No valid sample there, or one more than thr below the plane (into the material).
    bool empty_or_below(std::int64_t k, std::int64_t i) {
        const Side s = side(k, i);
        return s == Side::kNone || s == Side::kBelow;
    }

  private:
    enum class Side : std::uint8_t { kUnknown, kNone, kOn, kAbove, kBelow };
    Side side(std::int64_t k, std::int64_t i);
    const FaceFrame& fr_;
    const PlaneFit& plane_;
    double thr_;
    std::int64_t k0_, i0_, cols_;
    std::vector<Side> side_;
};

double sample_std(const std::vector<double>& v);
// Iterative k·σ rejection around the mean.
struct MeanFit {
    double mean = kNaN, std = kNaN;
    std::int64_t n = 0;
};
MeanFit robust_mean(const std::vector<double>& v, double k_sigma);

constexpr std::int64_t kNeighbours[4][2] = {{0, 1}, {0, -1}, {1, 0}, {-1, 0}};

// Edge samples between a surface and whatever lies beyond it. `on(k,i)` tells whether a sample
// is on the surface; `cross(k,i)` gives the range s where sample (k, i)'s ray meets the surface
// (NaN if it does not); `keep(A, B)` accepts a bracket by position (side, window). The edge lies
// between the two rays' crossings A (last sample on the surface) and B (first one beyond).
struct Bracket {
    Eigen::Vector3d A, B;
    std::int64_t k = 0;  // A's profile
};
template <class On, class Cross, class Keep>
std::vector<Bracket> bracket_edges(const FaceFrame& fr, const std::vector<std::int64_t>& seeds,
                                   double thr, double max_gap, On on, Cross cross, Keep keep) {
    std::vector<Bracket> out;
    for (std::int64_t q : seeds) {
        const std::int64_t k = q / fr.w, i = q % fr.w;
        for (const auto& nb : kNeighbours) {
            const std::int64_t kb = k + nb[0], ib = i + nb[1];
            if (kb < 0 || kb >= fr.n || ib < 0 || ib >= fr.w || fr.left_out(kb)) continue;
            // On the surface too (most neighbours): no edge between, whatever its crossing.
            if (fr.valid(kb, ib) && on(kb, ib)) continue;
            const double sb = cross(kb, ib);
            if (std::isnan(sb)) continue;
            // Beyond the edge: no return, or a return farther from the sensor than the surface.
            auto beyond = [&](std::int64_t kk, std::int64_t ii, double s_surface) {
                if (kk < 0 || kk >= fr.n || ii < 0 || ii >= fr.w || !fr.valid(kk, ii)) return true;
                return !on(kk, ii) && fr.range(kk, ii) > s_surface + thr;
            };
            if (!beyond(kb, ib, sb)) continue;
            if (!fr.valid(kb, ib)) {
                // A lone dropout on the surface is not an edge: the sample after it must be
                // beyond as well.
                const std::int64_t kc = kb + nb[0], ic = ib + nb[1];
                if (fr.left_out(kc)) continue;  // unknown, not beyond
                if (kc >= 0 && kc < fr.n && ic >= 0 && ic < fr.w) {
                    const double sc = cross(kc, ic);
                    if (std::isnan(sc) || !beyond(kc, ic, sc)) continue;
                }
            }
            const double sa = cross(k, i);
            if (std::isnan(sa)) continue;
            const Eigen::Vector3d A = fr.ray_origin(k, i) + sa * fr.ray_dir(i);
            const Eigen::Vector3d B = fr.ray_origin(kb, ib) + sb * fr.ray_dir(ib);
            if ((A - B).norm() > max_gap || !keep(A, B)) continue;
            out.push_back({A, B, k});
        }
    }
    return out;
}

// The edge as the coordinate most brackets agree on (interval stabbing). Every bracket contains
// the true edge up to the ray and surface errors (µm), so where brackets are not dithered across
// the sampling grid (a straight edge seen by fixed rays) their intersection pins the edge far
// better than the mean of midpoints, whose error would be up to half a spacing.
struct Interval {
    double lo, hi;
};
struct IntervalEstimate {
    double value = kNaN;
    double u = kNaN;             // standard uncertainty: width of the agreed region / √12
    double midpoint_std = kNaN;  // spread of the bracket midpoints (the sampling's own scatter)
    std::int64_t n_used = 0;     // brackets containing the agreed region
};
IntervalEstimate stab(const std::vector<Interval>& iv);

// Circle through brackets [A, B] in a plane (A on the surface, B beyond): the circle that
// crosses every bracket, with a weak pull towards the midpoints (docs/measurement.md, step 3).
struct BracketCircle {
    Eigen::Vector2d center;
    double radius = 0;
    std::int64_t n_used = 0;
};
BracketCircle fit_circle_brackets(
    const std::vector<std::pair<Eigen::Vector2d, Eigen::Vector2d>>& br, const Eigen::Vector2d& c0,
    double r0);

}  // namespace hotgauge::measure::detail
