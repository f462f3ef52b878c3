// Diameters (docs/measurement.md, "Edges and circles", paper §4.3.2): the level's plane, a coarse
// edge from grid normals, brackets of neighbouring rays across the edge, a circle through the
// brackets; on a partial arc the radius about the part axis.
#include <algorithm>
#include <cmath>
#include <numbers>

#include "corner.hpp"
#include "drift.hpp"
#include "edges.hpp"
#include "feature_kinds.hpp"

namespace hotgauge::measure::detail {
namespace {

using Pair2d = std::pair<Eigen::Vector2d, Eigen::Vector2d>;

// The fine circle through the bracket midpoints: 3σ rejection, never tighter than 0.02 mm (the
// brackets missed by more are misclassified samples, docs/measurement.md "Edges and circles").
constexpr RejectOptions kFineReject{3.0, 0.02, 10};
// Arc coverage in 36 bins of 10° (not measured).
constexpr int kArcBins = 36;
constexpr double kArcBinDeg = 10.0;
// A sector's diameter counts from at least this many midpoints, or a quarter of an even share
// (not measured).
constexpr int kMinInSector = 5, kSectorShareDivisor = 4;
// On a partial arc, the free fit may disagree by its 3 u, or the configured limit
// (docs/measurement.md: max(0.05 mm, 3 u)).
constexpr double kDisagreementK = 3.0;

// On-plane samples near the expected edge radius (the bracket seeds, per face) and, among them,
// the coarse edge points: a grid normal leaving the plane normal (paper §4.3.2) or a neighbour
// beyond the plane.
void coarse_edge(const Context& ctx, const core::FeatureSpec& f,
                 const std::vector<const FaceFrame*>& frames, const EdgePlane& ep, double R_e,
                 double win, std::vector<Eigen::Vector2d>& coarse,
                 std::vector<std::vector<std::int64_t>>& seeds) {
    const double cos_edge = std::cos(ctx.c.normal_edge_deg / kRadToDeg);
    const double band = ctx.ex.tol(ctx.c.plane_band_mm, ctx.level_z(f.edge_at));
    const PlaneFit& plane = ep.plane;
    seeds.assign(frames.size(), {});
    for (std::size_t fi = 0; fi < frames.size(); ++fi) {
        const FaceFrame& fr = *frames[fi];
        // The plane samples near the edge first, then each tested for an edge next to it.
        std::vector<std::pair<std::int64_t, Eigen::Vector3d>> on_plane;
        std::int64_t k_lo = fr.n, k_hi = -1, i_lo = fr.w, i_hi = -1;
        fr.for_z(plane.point.z() - band, plane.point.z() + band, [&](const FaceFrame::Near& s) {
            if (std::abs(s.r - R_e) > win) return;
            const Eigen::Vector3d p = s.p.cast<double>();
            if (std::abs(plane.distance(p)) > ep.thr) return;
            on_plane.emplace_back(s.q, p);
            k_lo = std::min(k_lo, s.q / fr.w), k_hi = std::max(k_hi, s.q / fr.w);
            i_lo = std::min(i_lo, s.q % fr.w), i_hi = std::max(i_hi, s.q % fr.w);
        });
        PlaneSides sides(fr, plane, ep.thr, k_lo, k_hi, i_lo, i_hi);
        for (const auto& [q, p] : on_plane) {
            seeds[fi].push_back(q);
            const std::int64_t k = q / fr.w, i = q % fr.w;
            bool edge = false;
            for (const auto& nb : kNeighbours) {
                const std::int64_t kn = k + nb[0], in = i + nb[1];
                if (fr.left_out(kn)) continue;  // unknown, not beyond the edge
                if (sides.empty_or_below(kn, in)) edge = true;
            }
            if (!edge && !sides.flat_around(k, i)) {
                const auto nrm = grid_normal(fr, k, i);
                edge = nrm && std::abs(nrm->dot(plane.normal)) < cos_edge;
            }
            if (edge) coarse.push_back(ep.to2d(p));
        }
    }
}

// Which profiles of which faces held plane samples near the edge, for a reason.
std::string profile_span(const std::vector<const FaceFrame*>& frames,
                         const std::vector<std::vector<std::int64_t>>& seeds) {
    std::string out;
    for (std::size_t fi = 0; fi < frames.size(); ++fi) {
        if (!out.empty()) out += ", ";
        out += frames[fi]->scan->name;
        if (seeds[fi].empty()) {
            out += ": no plane samples near the edge";
            continue;
        }
        const auto [lo, hi] = std::minmax_element(seeds[fi].begin(), seeds[fi].end());
        out += " profiles " + std::to_string(*lo / frames[fi]->w) + "–" +
               std::to_string(*hi / frames[fi]->w);
    }
    return out;
}

// A sample's face (index in the frames) and profile.
using SampleAt = std::pair<std::size_t, std::int64_t>;

// Brackets across the edge within `window` of the circle (cc, rc), as 2D pairs (A, B), and
// where each was seen.
std::vector<Pair2d> edge_brackets(const Context& ctx, const std::vector<const FaceFrame*>& frames,
                                  const EdgePlane& ep,
                                  const std::vector<std::vector<std::int64_t>>& seeds,
                                  bool plane_inside, const Eigen::Vector2d& cc, double rc,
                                  double window, std::vector<SampleAt>& at) {
    std::vector<Pair2d> out;
    at.clear();
    for (std::size_t fi = 0; fi < frames.size(); ++fi) {
        const FaceFrame& fr = *frames[fi];
        auto on = [&](std::int64_t k, std::int64_t i) {
            return std::abs(ep.plane.distance(fr.point(k, i))) <= ep.thr;
        };
        auto cross = [&](std::int64_t k, std::int64_t i) {
            return cross_plane(ep.plane, fr.ray_origin(k, i), fr.ray_dir(i));
        };
        auto keep = [&](const Eigen::Vector3d& A, const Eigen::Vector3d& B) {
            const double ra = (ep.to2d(A) - cc).norm(), rb = (ep.to2d(B) - cc).norm();
            const double rm = (ep.to2d(0.5 * (A + B)) - cc).norm();
            return (plane_inside ? ra < rb : ra > rb) && std::abs(rm - rc) <= window;
        };
        for (const auto& b :
             bracket_edges(fr, seeds[fi], ep.thr, ctx.c.max_pair_gap_mm, on, cross, keep)) {
            out.emplace_back(ep.to2d(b.A), ep.to2d(b.B));
            at.emplace_back(fi, b.k);
        }
    }
    return out;
}

// Two passes of midpoint circles: a wide window around the coarse circle, then a narrow one
// around the first fine circle. Returns the inlier brackets and the last midpoint fit.
struct FineEdge {
    std::vector<Pair2d> brackets;  // inliers of the midpoint fit
    std::vector<SampleAt> at;      // ... where each was seen
    std::vector<Eigen::Vector2d> midpoints;
    CircleFit fit;
};
std::optional<FineEdge> fine_edge(const Context& ctx, const core::FeatureSpec& f,
                                  const std::vector<const FaceFrame*>& frames, const EdgePlane& ep,
                                  const std::vector<std::vector<std::int64_t>>& seeds,
                                  bool plane_inside, const CircleFit& coarse, std::string& why) {
    Eigen::Vector2d cc = coarse.center;
    double rc = coarse.radius, window = ctx.c.fine_window_mm;
    FineEdge out;
    for (int pass = 0; pass < 2; ++pass) {
        std::vector<SampleAt> at;
        const auto br = edge_brackets(ctx, frames, ep, seeds, plane_inside, cc, rc, window, at);
        std::vector<Eigen::Vector2d> mids;
        for (const auto& [A, B] : br) mids.push_back(0.5 * (A + B));
        if (static_cast<int>(mids.size()) < ctx.c.min_edge_points) {
            why = "edge of '" + f.section + "': only " + std::to_string(mids.size()) +
                  " bracketed edge samples, " + std::to_string(ctx.c.min_edge_points) +
                  " needed (" + profile_span(frames, seeds) + ")";
            return std::nullopt;
        }
        auto fit = fit_circle_robust(mids, kFineReject);
        if (!fit) {
            why = "edge circle: " + fit.error().message;
            return std::nullopt;
        }
        out = {};
        for (std::size_t q = 0; q < br.size(); ++q)
            if (fit->inlier[q]) {
                out.brackets.push_back(br[q]);
                out.at.push_back(at[q]);
                out.midpoints.push_back(mids[q]);
            }
        out.fit = fit->fit;
        cc = fit->fit.center;
        rc = fit->fit.radius;
        window = ctx.c.refine_window_mm;
    }
    return out;
}

// The compensation's own error in the diameter (drift.hpp): twice the mean of the brackets'
// displacement error away from the centre.
DriftSum edge_drift(const std::vector<const FaceFrame*>& frames, const EdgePlane& ep,
                    const FineEdge& fe, const Eigen::Vector2d& centre) {
    DriftSum d;
    if (fe.brackets.empty()) return d;
    const auto n = static_cast<double>(fe.brackets.size());
    for (std::size_t q = 0; q < fe.brackets.size(); ++q)
        add_radial(d, *frames[fe.at[q].first], fe.at[q].second,
                   (fe.midpoints[q] - centre).normalized(), ep.e1, ep.e2, n);
    return d;
}

// Arc coverage in 10° bins and the sector diameters (multiple sampling, paper §4.3).
void coverage(const Context& ctx, const FineEdge& fe, FeatureResult& r,
              std::vector<double>& sector_d) {
    std::vector<int> bins(kArcBins, 0);
    const int ns = std::max(1, ctx.c.sectors);
    std::vector<double> ssum(ns, 0.0);
    std::vector<int> scnt(ns, 0);
    for (const auto& m : fe.midpoints) {
        const Eigen::Vector2d d = m - fe.fit.center;
        const double turn = (std::atan2(d.y(), d.x()) + std::numbers::pi) / (2 * std::numbers::pi);
        bins[std::min(kArcBins - 1, static_cast<int>(turn * kArcBins))]++;
        const int s = std::min(ns - 1, static_cast<int>(turn * ns));
        ssum[s] += d.norm();
        scnt[s]++;
    }
    int covered = 0;
    for (int b : bins) covered += b > 0;
    r.arc_deg = kArcBinDeg * covered;
    const int min_in_sector =
        std::max(kMinInSector, static_cast<int>(fe.fit.n_points / (kSectorShareDivisor * ns)));
    for (int s = 0; s < ns; ++s)
        if (scnt[s] >= min_in_sector) sector_d.push_back(2.0 * ssum[s] / scnt[s]);
}

// The radius (nearly) all brackets agree on about a centre (interval stabbing): robust to the few
// brackets that lie wholly inside the material (a dropout next to the edge taken for the region
// beyond it), which would drag a least-squares circle inwards; u is the agreed width / √12.
IntervalEstimate agreed_radius(const std::vector<Pair2d>& brackets, const Eigen::Vector2d& c) {
    std::vector<Interval> radial;
    for (const auto& [A, B] : brackets) {
        const double ra = (A - c).norm(), rb = (B - c).norm();
        radial.push_back({std::min(ra, rb), std::max(ra, rb)});
    }
    return stab(radial);
}

// On a partial arc centre and radius trade off: the radius all brackets agree on about the part
// axis (which the pose gives), refused when a free fit disagrees by more than its noise allows.
bool partial_arc_radius(const Context& ctx, const core::FeatureSpec& f, const EdgePlane& ep,
                        const FineEdge& fe, const BracketCircle& bc, FeatureResult& r,
                        double& radius, double& u_arc) {
    const IntervalEstimate e = agreed_radius(fe.brackets, ep.axis2d());
    // The free fit's disagreement carries the pose's axis error: it enters u in full, and beyond
    // what the free fit's own noise explains the value is not trusted at all.
    const double disagreement = std::abs(e.value - bc.radius);
    const double limit =
        std::max(ctx.c.max_partial_arc_disagreement_mm, kDisagreementK * fe.fit.u_radius_mm);
    if (disagreement > limit) {
        r.reason = "edge of '" + f.section + "' on " + std::to_string(static_cast<int>(r.arc_deg)) +
                   "° of arc: centred on the part axis its radius differs by " +
                   std::to_string(disagreement) + " mm from a free fit: pose off or edge distorted";
        return false;
    }
    radius = e.value;
    u_arc = disagreement;
    return true;
}

// The level plane with its normal towards the sensor, or why not.
std::optional<EdgePlane> edge_plane(const Context& ctx, const core::FeatureSpec& f,
                                    const std::vector<const FaceFrame*>& frames, double R,
                                    bool& plane_inside, std::string& why) {
    const auto ann = ctx.annulus(f.edge_at, R, frames, why);
    if (!ann) return std::nullopt;
    plane_inside = ann->hi == R;  // the plane lies at r < R (outer edge)
    PlaneResult pl = ctx.level_plane(f.edge_at, *ann, frames);
    if (!pl.error.empty()) {
        why = pl.error;
        return std::nullopt;
    }
    EdgePlane ep;
    ep.plane = pl.fit;
    if (ep.plane.normal.dot(frames.front()->view) > 0) ep.plane.normal = -ep.plane.normal;
    ep.thr = surface_threshold(ep.plane.rms_mm, ctx.c);
    ep.profile_scatter = profile_scatter(pl);
    ep.e1 = ep.plane.normal.unitOrthogonal();
    ep.e2 = ep.plane.normal.cross(ep.e1);
    return ep;
}

// The faces that see the edge's plane and, on a forging whose recipe adds faces that see the wall
// broadside (the side scans), those: the wall's draft comes from them, the edge's level from the
// others.
struct EdgeFaces {
    std::vector<const FaceFrame*> plane, wall;
};
EdgeFaces edge_faces(const Context& ctx, const core::FeatureSpec& f,
                     const std::vector<const FaceFrame*>& all) {
    EdgeFaces out;
    for (const auto* fr : all)
        (!ctx.recipe.forging || sees_edge_plane(ctx, f, *fr) ? out.plane : out.wall).push_back(fr);
    if (out.plane.empty()) out.plane = all;  // none sees it: the reason names them
    return out;
}

// The coarse edge (docs/measurement.md, "Edges and circles", step 1): a robust circle through
// the coarse edge points near the expected radius R_e (± win), with the bracket seeds; or why not.
std::optional<CircleFit> coarse_circle(const Context& ctx, const core::FeatureSpec& f,
                                       const std::vector<const FaceFrame*>& frames,
                                       const EdgePlane& ep, double R_e, double win,
                                       std::vector<std::vector<std::int64_t>>& seeds,
                                       std::string& why) {
    // 3σ rejection, never tighter than 0.1 mm (the fine circle's is 0.02 mm).
    constexpr RejectOptions kCoarseReject{3.0, 0.1, 10};
    std::vector<Eigen::Vector2d> coarse;
    coarse_edge(ctx, f, frames, ep, R_e, win, coarse, seeds);
    if (static_cast<int>(coarse.size()) < ctx.c.min_edge_points) {
        why = "edge of '" + f.section + "' at '" + f.edge_at + "': only " +
              std::to_string(coarse.size()) + " edge points near the expected radius, " +
              std::to_string(ctx.c.min_edge_points) + " needed (" + profile_span(frames, seeds) +
              ")";
        return std::nullopt;
    }
    auto fit = fit_circle_robust(coarse, kCoarseReject);
    if (!fit) {
        why = "coarse edge circle: " + fit.error().message;
        return std::nullopt;
    }
    return fit->fit;
}

// The bracket circle's centre in 3D, refused (why) unless it lies on the part axis (the pose put
// it there) and its radius in the window about R_e: otherwise these are not the edge's points.
std::optional<Eigen::Vector3d> centre_on_axis(const Context& ctx, const core::FeatureSpec& f,
                                              const EdgePlane& ep, const BracketCircle& bc,
                                              double R_e, double win, std::string& why) {
    const Eigen::Vector3d centre = ep.plane.point + bc.center.x() * ep.e1 + bc.center.y() * ep.e2;
    const double off_axis = centre.head<2>().norm();
    if (off_axis > ctx.c.max_axis_offset_mm || std::abs(bc.radius - R_e) > win) {
        why = "edge circle of '" + f.section + "' is " + std::to_string(off_axis) +
              " mm off the part axis, radius " + std::to_string(bc.radius) +
              " mm: wrong pose or wrong part";
        return std::nullopt;
    }
    return centre;
}

// The diameter's uncertainty budget: the midpoint fit's, the sampling's (the width the brackets
// agree on), the compensation's (profiles' scatter off the plane and the brackets' drift), and on
// a partial arc the free fit's disagreement (u_arc, as a radius).
std::vector<std::pair<std::string, double>> diameter_budget(
    const std::vector<const FaceFrame*>& frames, const EdgePlane& ep, const FineEdge& fe,
    const Eigen::Vector2d& centre, double u_sampling, double u_arc) {
    const DriftSum drift = edge_drift(frames, ep, fe, centre);
    std::vector<std::pair<std::string, double>> budget = {
        {"fit", 2.0 * fe.fit.u_radius_mm},
        {"sampling", 2.0 * u_sampling},
        {"compensation", std::hypot(ep.profile_scatter, drift.u())}};
    add_holes_term(budget, drift);
    if (u_arc > 0) budget.push_back({"partial arc", 2.0 * u_arc});
    return budget;
}

}  // namespace

bool sees_edge_plane(const Context& ctx, const core::FeatureSpec& f, const FaceFrame& frame) {
    std::string unused;
    const double R = 0.5 * ctx.recipe.section(f.section)->diameter_mm;
    return ctx.annulus(f.edge_at, R, {&frame}, unused).has_value();
}

void measure_diameter(const Context& ctx, const core::FeatureSpec& f,
                      const std::vector<const FaceFrame*>& all, FeatureResult& r,
                      CornerMemo* memo) {
    const double R = 0.5 * ctx.recipe.section(f.section)->diameter_mm;
    const EdgeFaces faces = edge_faces(ctx, f, all);
    const std::vector<const FaceFrame*>& frames = faces.plane;
    bool plane_inside = false;
    const auto ep = edge_plane(ctx, f, frames, R, plane_inside, r.reason);
    if (!ep) return;
    CornerMemo own;
    if (ctx.recipe.forging && corner_diameter(ctx, f, frames, faces.wall, *ep,
                                              plane_inside ? 1.0 : -1.0, r, memo ? *memo : own))
        return;
    const double R_e = ctx.ex.z(R), win = ctx.ex.tol(ctx.c.edge_window_mm, R);
    std::vector<std::vector<std::int64_t>> seeds;
    const auto coarse = coarse_circle(ctx, f, frames, *ep, R_e, win, seeds, r.reason);
    if (!coarse) return;
    const auto fe = fine_edge(ctx, f, frames, *ep, seeds, plane_inside, *coarse, r.reason);
    if (!fe) return;
    std::vector<double> sector_d;
    coverage(ctx, *fe, r, sector_d);
    r.low_coverage = r.arc_deg < ctx.c.free_centre_min_arc_deg;
    if (r.arc_deg < ctx.c.min_arc_deg) {
        r.reason = "edge seen on only " + std::to_string(static_cast<int>(r.arc_deg)) + "° of arc";
        return;
    }
    // The midpoint fit is unbiased only where the edge is dithered across the sampling grid; the
    // bracket fit keeps the circle inside every bracket and so removes what is left.
    const BracketCircle bc = fit_circle_brackets(fe->brackets, fe->fit.center, fe->fit.radius);
    const auto centre = centre_on_axis(ctx, f, *ep, bc, R_e, win, r.reason);
    if (!centre) return;
    // Full circle: the radius the brackets agree on about the bracket circle's centre. Partial
    // arc: centre and radius trade off, so about the part axis (partial_arc_radius).
    const IntervalEstimate agreed = agreed_radius(fe->brackets, bc.center);
    double radius = agreed.value, u_arc = 0;
    if (r.arc_deg < ctx.c.free_centre_min_arc_deg &&
        !partial_arc_radius(ctx, f, *ep, *fe, bc, r, radius, u_arc))
        return;
    r.hot_mm = 2.0 * radius;
    r.u_budget = diameter_budget(frames, *ep, *fe, bc.center, agreed.u, u_arc);
    r.fit_rms_mm = fe->fit.rms_mm;
    r.n_points = fe->fit.n_points;
    r.method = "edge circle";
    r.n_sectors = static_cast<int>(sector_d.size());
    if (sector_d.size() >= 2) r.sector_spread_mm = sample_std(sector_d);
    add_sector_term(r);
    r.ends.push_back({f.edge_at, "silhouette edge", f.faces, radius, 0.5 * r.u_mm, r.n_points});
    r.centre_mm = *centre;
}

}  // namespace hotgauge::measure::detail
