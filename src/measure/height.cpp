// Heights (docs/measurement.md, "Heights"). `method: planes`: both levels' fitted planes.
// `method: edges` (side scans): each end by what its faces see — the level's face with the wall
// below or above it (convex corner: the fitted face), the wall standing on the support plate
// (concave corner: the fitted plate), or the wall alone (silhouette edge: brackets of neighbouring
// rays, interval stabbing).
#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <numbers>

#include "drift.hpp"
#include "edges.hpp"
#include "feature_kinds.hpp"

namespace hotgauge::measure::detail {
namespace {

using Segment = core::AxisymmetricSolid::Segment;
// A wall whose lowest sample lies farther above its standing level than this does not stand on
// the plate (a few samples' spacing along the laser line, plus noise).
constexpr double kMaxRimGapMm = 0.5;
// A floor on a plane's point spread (mm² per in-plane direction), so that points in one spot
// give a finite lever term (not measured).
constexpr double kMinSpread2Mm2 = 1e-6;
// The 3σ rejection of the other robust fits (fit.hpp), for the wall's radius.
constexpr double kWallRejectK = 3.0;
// The support plate is fitted out to this beyond the part's largest radius (hot, mm), as the
// part's bounding cylinder (docs/measurement.md; not measured).
constexpr double kPlateBeyondPartMm = 5.0;
// The wall's lowest sample is looked for within this of where it would stand (not measured).
constexpr double kRimSearchMm = 2.0;
// A sector with fewer brackets or plane points than this on either end is left out of the
// sectors' spread (not measured).
constexpr int kMinPerSector = 10;

// One end of a height: what the JSON reports, and the geometry the height is taken from.
struct LevelEnd {
    EdgeEstimate est;
    std::optional<PlaneFit> plane;                  // plane-derived ends
    std::vector<Eigen::Vector3d> plane_points;      // ... a convex corner's: the plane's inliers
    std::vector<std::int64_t> plane_keys;           // ... their profiles (PlaneResult)
    std::vector<const FaceFrame*> plane_frames;     // ... the faces the keys count in
    Eigen::Vector3d ref = Eigen::Vector3d::Zero();  // the end's point (on the plane at the wall)
    std::vector<double> angles;                     // silhouette: azimuth of each bracket
    std::vector<Interval> intervals;                // silhouette: each bracket's z interval
    double u_fit = 0;                               // est.u_mm's share from the end's own fit ...
    double u_pose = 0;  // ... and from the pose's axis: est.u_mm = hypot(u_fit, u_pose)
};

// Standard uncertainty of a plane's height at `p` from its points: offset and tilt (lever arm).
double plane_u_at(const PlaneResult& pl, const Eigen::Vector3d& p) {
    const double n = static_cast<double>(std::max<std::int64_t>(pl.fit.n_points, 1));
    double spread2 = 0;
    for (const auto& q : pl.points) spread2 += (q - pl.fit.point).squaredNorm();
    spread2 = std::max(spread2 / n / 2.0, kMinSpread2Mm2);  // per in-plane direction
    const Eigen::Vector3d d = p - pl.fit.point;
    const double lever2 = (d - pl.fit.normal * pl.fit.normal.dot(d)).squaredNorm();
    return pl.fit.rms_mm / std::sqrt(n) * std::sqrt(1.0 + lever2 / spread2);
}

// The point of the plane at radius R about the axis, at azimuth phi.
Eigen::Vector3d on_plane_at(const PlaneFit& pl, double R, double phi) {
    const double x = R * std::cos(phi), y = R * std::sin(phi);
    const double z =
        pl.point.z() -
        (pl.normal.x() * (x - pl.point.x()) + pl.normal.y() * (y - pl.point.y())) / pl.normal.z();
    return {x, y, z};
}

// The outermost wall that ends at `level` (its convex edge there), or null.
const Segment* outer_wall(const Context& ctx, double L) {
    const Segment* wall = nullptr;
    for (const auto& s : ctx.solid.boundary())
        if (s.cylinder && (s.lo == L || s.hi == L) &&
            ctx.solid.inside(s.value - 1e-6, 0.5 * (s.lo + s.hi)) &&
            (!wall || s.value > wall->value))
            wall = &s;
    return wall;
}

// The wall's samples, away from its ends: radius about the axis (robust mean), azimuth.
struct WallFit {
    MeanFit radius;
    double thr = 0;  // on-wall threshold
    double phi = 0;  // mean azimuth of the samples seen
    std::int64_t profile_lo = 0, profile_hi = -1;
};
std::optional<WallFit> fit_wall(const Context& ctx, const std::vector<const FaceFrame*>& frames,
                                const Segment& wall, const std::string& level, std::string& why) {
    // A forged wall: clear of its fillets, and its draft widens the band of radii it spans.
    double lean = 0, m = ctx.c.support_margin_mm;
    if (ctx.recipe.forging) {
        lean = std::tan(ctx.recipe.forging->draft_deg / kRadToDeg) * 0.5 * (wall.hi - wall.lo);
        m += ctx.recipe.forging->fillet_mm;
    }
    const double R_e = ctx.ex.z(wall.value),
                 band = ctx.ex.tol(ctx.c.wall_band_mm + lean, wall.value);
    // The whole wall: the solid splits a cylinder at every level that crosses it.
    double lo = wall.lo, hi = wall.hi;
    for (bool grew = true; grew;) {
        grew = false;
        for (const auto& s : ctx.solid.boundary())
            if (s.cylinder && s.value == wall.value && (s.hi == lo || s.lo == hi)) {
                lo = std::min(lo, s.lo);
                hi = std::max(hi, s.hi);
                grew = true;
            }
    }
    const double z_lo = ctx.ex.z(lo) + ctx.ex.tol(m, lo), z_hi = ctx.ex.z(hi) - ctx.ex.tol(m, hi);
    std::vector<double> radii;
    double sx = 0, sy = 0;
    WallFit w;
    w.profile_lo = std::numeric_limits<std::int64_t>::max();
    for (const auto* fr : frames)
        fr->for_z(z_lo, z_hi, [&](const FaceFrame::Near& s) {
            if (s.p.z() < z_lo || s.p.z() > z_hi || std::abs(s.r - R_e) > band) return;
            radii.push_back(s.r);
            sx += s.p.x();
            sy += s.p.y();
            w.profile_lo = std::min(w.profile_lo, s.q / fr->w);
            w.profile_hi = std::max(w.profile_hi, s.q / fr->w);
        });
    if (static_cast<int>(radii.size()) < ctx.c.min_plane_points) {
        why = "wall ending at level '" + level + "': only " + std::to_string(radii.size()) +
              " points where it should be";
        return std::nullopt;
    }
    w.radius = robust_mean(radii, kWallRejectK);
    w.thr = surface_threshold(w.radius.std, ctx.c);
    w.phi = std::atan2(sy, sx);
    return w;
}

// Convex corner: the level's own face next to the wall is seen, so the edge is where the fitted
// face meets the wall (no sampling of the edge itself, no bias from where samples fall).
std::optional<LevelEnd> corner_end(const Context& ctx, const std::string& level,
                                   const Segment& wall, const WallFit& w,
                                   const std::vector<const FaceFrame*>& frames, std::string& why) {
    std::string no_face;
    const auto ann = ctx.annulus(level, wall.value, frames, no_face);
    if (!ann) return std::nullopt;  // not a face these sensors see: not an error
    PlaneResult pl = ctx.level_plane(level, *ann, frames);
    if (!pl.error.empty()) {
        why = pl.error;
        return std::nullopt;
    }
    LevelEnd e;
    e.plane = pl.fit;
    e.ref = on_plane_at(pl.fit, w.radius.mean, w.phi);
    e.u_fit = plane_u_at(pl, e.ref);
    e.plane_points = std::move(pl.points);
    e.plane_keys = std::move(pl.profile_keys);
    e.plane_frames = frames;
    e.est = {level, "convex corner", {}, e.ref.z(), e.u_fit, pl.fit.n_points};
    return e;
}

// Concave corner on the support plate: the part's lowest level, seen from above, with its wall
// coming down to a plate that fills the level beyond it. A part standing on the rim of that
// level touches the plate with the rim's lowest point, wherever the part's axis leans: the level
// is the plane across the axis whose rim circle (radius R) just touches the fitted plate. With
// the plate n·(p − p0) = 0 in the part frame, that is z = (n·p0 + R·|n_xy|) / n_z.
std::optional<LevelEnd> support_end(const Context& ctx, const std::string& level, double L,
                                    const Segment& wall, const WallFit& w,
                                    const std::vector<const FaceFrame*>& frames, std::string& why) {
    double z_min = std::numeric_limits<double>::max();
    for (const auto& [name, z] : ctx.recipe.levels_mm) z_min = std::min(z_min, z);
    for (const auto* fr : frames)
        if (fr->view.z() >= 0) return std::nullopt;  // a sensor that cannot see the plate's top
    if (L != z_min || wall.lo != L) return std::nullopt;
    const double m = ctx.c.support_margin_mm;
    const PlaneResult pl = fit_level_plane(frames, ctx.ex.z(L), ctx.ex.tol(ctx.c.plane_band_mm, L),
                                           ctx.ex.z(wall.value) + ctx.ex.tol(m, wall.value),
                                           ctx.ex.z(ctx.solid.max_radius()) + kPlateBeyondPartMm,
                                           ctx.c, "support plate at level '" + level + "'");
    if (!pl.error.empty()) {
        why = pl.error;
        return std::nullopt;
    }
    PlaneFit plate = pl.fit;
    if (plate.normal.z() < 0) plate.normal = -plate.normal;
    const double R = w.radius.mean;
    const double z_end =
        (plate.normal.dot(plate.point) + R * plate.normal.head<2>().norm()) / plate.normal.z();
    // The part stands on the plate only if its wall comes down to that level where it is seen.
    const double thr = surface_threshold(plate.rms_mm, ctx.c);
    double lowest = std::numeric_limits<double>::max();
    for (const auto* fr : frames)
        fr->for_z(z_end - kRimSearchMm, z_end + kRimSearchMm, [&](const FaceFrame::Near& s) {
            if (std::abs(s.r - R) <= w.thr && plate.distance(s.p.cast<double>()) > thr)
                lowest = std::min(lowest, static_cast<double>(s.p.z()));
        });
    if (lowest > z_end + kMaxRimGapMm + ctx.recipe.fillet_at(level)) {
        why = "the wall ending at level '" + level + "' stops " + std::to_string(lowest - z_end) +
              " mm above where it would stand on the support plate: the part is not on the plate";
        return std::nullopt;
    }
    LevelEnd e;
    e.ref = {0.0, 0.0, z_end};
    // The lean of the axis against the plate comes from the pose: its error moves the rim by R·δ.
    e.u_pose = R * ctx.c.pose_axis_u_deg / kRadToDeg;
    e.u_fit = plane_u_at(pl, e.ref);
    e.est = {level, "concave corner", {}, z_end, std::hypot(e.u_fit, e.u_pose), pl.fit.n_points};
    return e;
}

// Silhouette edge: only the wall is seen. Brackets along the laser line between the last sample
// on the wall and the first beyond it (no return, or farther than the wall); their crossings
// with the wall cylinder are z intervals, and the edge is where (nearly) all of them overlap.
std::optional<LevelEnd> silhouette_end(const Context& ctx, const std::string& level, double L,
                                       const Segment& wall, const WallFit& w,
                                       const std::vector<const FaceFrame*>& frames,
                                       std::string& why) {
    const bool wall_below = wall.hi == L;
    const double L_e = ctx.ex.z(L), win = ctx.ex.tol(ctx.c.edge_window_mm, L);
    LevelEnd e;
    for (const auto* frp : frames) {
        const FaceFrame& fr = *frp;
        std::vector<std::int64_t> seeds;
        auto on = [&](std::int64_t k, std::int64_t i) {
            return std::abs(fr.radius(k, i) - w.radius.mean) <= w.thr;
        };
        fr.for_z(L_e - win, L_e + win, [&](const FaceFrame::Near& s) {
            if (std::abs(s.p.z() - L_e) <= win && std::abs(s.r - w.radius.mean) <= w.thr)
                seeds.push_back(s.q);
        });
        auto cross = [&](std::int64_t k, std::int64_t i) {
            return cross_cylinder(w.radius.mean, fr.ray_origin(k, i), fr.ray_dir(i));
        };
        auto keep = [&](const Eigen::Vector3d& A, const Eigen::Vector3d& B) {
            return wall_below ? A.z() < B.z() : A.z() > B.z();
        };
        for (const auto& b :
             bracket_edges(fr, seeds, w.thr, ctx.c.max_pair_gap_mm, on, cross, keep)) {
            e.intervals.push_back({std::min(b.A.z(), b.B.z()), std::max(b.A.z(), b.B.z())});
            e.angles.push_back(std::atan2(b.A.y(), b.A.x()));
        }
    }
    if (static_cast<int>(e.intervals.size()) < ctx.c.min_edge_points) {
        why = "edge at level '" + level + "' (silhouette of the wall r " +
              std::to_string(w.radius.mean) + " mm, profiles " + std::to_string(w.profile_lo) +
              "–" + std::to_string(w.profile_hi) + "): only " + std::to_string(e.intervals.size()) +
              " edge samples, " + std::to_string(ctx.c.min_edge_points) + " needed";
        return std::nullopt;
    }
    const IntervalEstimate s = stab(e.intervals);
    e.ref = {w.radius.mean * std::cos(w.phi), w.radius.mean * std::sin(w.phi), s.value};
    e.u_fit = s.u;
    e.est = {level, "silhouette edge", {}, s.value, s.u, s.n_used};
    return e;
}

// A forged part's end: a filleted edge's silhouette lies up to a fillet radius off its level, so
// the level's own face is fitted, from the side faces that see it, else from the other faces of
// the feature that do (the flange underside from the bottom scan); or the plate the part stands on.
constexpr double kSideViewZ = 0.7;  // a side sensor looks across the axis: |view·z| below this
std::optional<LevelEnd> forged_end(const Context& ctx, const std::string& level, double L,
                                   const Segment& wall, const WallFit& w,
                                   const std::vector<const FaceFrame*>& frames, std::string& why) {
    std::vector<const FaceFrame*> sets[2];  // side faces, then the others
    for (const auto* fr : frames) sets[std::abs(fr->view.z()) < kSideViewZ ? 0 : 1].push_back(fr);
    std::string why_corner, why_support, unused;
    for (const auto& set : sets) {
        std::vector<const FaceFrame*> facing;
        for (const auto* fr : set)
            if (ctx.annulus(level, wall.value, {fr}, unused)) facing.push_back(fr);
        if (facing.empty()) continue;
        if (auto e = corner_end(ctx, level, wall, w, facing, why_corner)) {
            for (const auto* fr : facing) e->est.faces.push_back(fr->scan->name);
            return e;
        }
    }
    if (!sets[0].empty())
        if (auto e = support_end(ctx, level, L, wall, w, sets[0], why_support)) {
            for (const auto* fr : sets[0]) e->est.faces.push_back(fr->scan->name);
            return e;
        }
    why = "level '" + level +
          "': its face is seen by none of the feature's faces, and a filleted " +
          "edge's silhouette is no level";
    for (const auto* extra : {&why_corner, &why_support})
        if (!extra->empty()) why += "; " + *extra;
    return std::nullopt;
}

// One end of a `method: edges` height, by the best estimator its faces allow.
std::optional<LevelEnd> level_end(const Context& ctx, const std::string& level,
                                  const std::vector<const FaceFrame*>& frames, std::string& why) {
    const double L = ctx.level_z(level);
    const Segment* wall = outer_wall(ctx, L);
    if (!wall) {
        why = "no outer wall ends at level '" + level + "'";
        return std::nullopt;
    }
    auto w = fit_wall(ctx, frames, *wall, level, why);
    if (!w && ctx.recipe.forging) {
        // A forging's end is its level's fitted face: the wall only places the point the height
        // is taken at, and a wall out of view (under the flange) is placed at its nominal.
        w = WallFit{};
        w->radius.mean = ctx.ex.z(wall->value);
        w->thr = ctx.ex.tol(ctx.c.wall_band_mm, wall->value);
        why.clear();
    }
    if (!w) return std::nullopt;
    if (ctx.recipe.forging) return forged_end(ctx, level, L, *wall, *w, frames, why);
    std::string why_corner, why_support;
    auto e = corner_end(ctx, level, *wall, *w, frames, why_corner);
    if (!e) e = support_end(ctx, level, L, *wall, *w, frames, why_support);
    if (!e) e = silhouette_end(ctx, level, L, *wall, *w, frames, why);
    if (!e) {
        for (const auto* extra : {&why_corner, &why_support})
            if (!extra->empty()) why += "; " + *extra;
        return std::nullopt;
    }
    for (const auto* fr : frames) e->est.faces.push_back(fr->scan->name);
    return e;
}

// The height between two ends: from the better-supported plane when an end has one (the other
// end's point, at the same side of the part, so a small tilt of the pose cancels), else along
// the axis between two edges.
// Two planes from different faces (a forging's flange top from the top scan, its underside from
// the bottom scan): along the axis, where neither plane's tilt error has a lever arm (at the
// flange rim, 69 mm out, a compensation residual's 0.5 mrad tilt of one face's plane read a
// height 0.035 mm off).
double height_between(const LevelEnd& a, const LevelEnd& b) {
    const LevelEnd* ref = nullptr;
    if (a.plane && (!b.plane || a.plane->n_points >= b.plane->n_points)) ref = &a;
    if (b.plane && !ref) ref = &b;
    if (!ref) return std::abs(b.ref.z() - a.ref.z());
    const LevelEnd& other = ref == &a ? b : a;
    if (other.plane && other.est.faces != ref->est.faces) {
        const PlaneFit& o = *other.plane;
        const Eigen::Vector3d on_axis(
            0.0, 0.0,
            o.point.z() + (o.normal.x() * o.point.x() + o.normal.y() * o.point.y()) / o.normal.z());
        return std::abs(ref->plane->distance(on_axis));
    }
    return std::abs(ref->plane->distance(other.ref));
}

// Sectors for two silhouette ends: the same estimate on each part of the observed angular span.
void edge_sectors(const Context& ctx, const LevelEnd (&e)[2], FeatureResult& r) {
    double lo = std::numeric_limits<double>::max(), hi = std::numeric_limits<double>::lowest();
    for (const auto& end : e)
        for (double a : end.angles) {
            lo = std::min(lo, a);
            hi = std::max(hi, a);
        }
    const int ns = std::max(1, ctx.c.sectors / 2);
    std::vector<double> hs, us;
    for (int sec = 0; sec < ns; ++sec) {
        std::vector<Interval> part[2];
        for (int j = 0; j < 2; ++j)
            for (std::size_t q = 0; q < e[j].intervals.size(); ++q)
                if (std::min(ns - 1, static_cast<int>((e[j].angles[q] - lo) / (hi - lo + 1e-12) *
                                                      ns)) == sec)
                    part[j].push_back(e[j].intervals[q]);
        if (part[0].size() < kMinPerSector || part[1].size() < kMinPerSector) continue;
        const IntervalEstimate a = stab(part[0]), b = stab(part[1]);
        hs.push_back(std::abs(b.value - a.value));
        us.push_back(std::hypot(a.u, b.u));
    }
    r.n_sectors = static_cast<int>(hs.size());
    if (hs.size() < 2) return;
    r.sector_spread_mm = sample_std(hs);
    // A sector with few brackets reads far off within its own wide uncertainty (measured: 11
    // brackets, 0.06 mm off, u 0.038 mm); the plain spread made u 0.02-0.6 mm for values a few
    // micrometres off. What varies around the part is the spread beyond that.
    if (const auto tau = between_std(hs, us)) r.sector_between_mm = *tau;
}

void plane_sectors(const Context& ctx, const PlaneResult (&pl)[2], FeatureResult& r);

void height_edges(const Context& ctx, const core::FeatureSpec& f,
                  const std::vector<const FaceFrame*>& frames, FeatureResult& r) {
    LevelEnd e[2];
    const std::string levels[2] = {f.from_level, f.to_level};
    for (int j = 0; j < 2; ++j) {
        auto end = level_end(ctx, levels[j], frames, r.reason);
        if (!end) return;
        e[j] = std::move(*end);
    }
    r.reason.clear();
    r.hot_mm = height_between(e[0], e[1]);
    r.n_points = e[0].est.n_points + e[1].est.n_points;
    r.u_budget = {{"fit", std::hypot(e[0].u_fit, e[1].u_fit)},
                  {"pose", std::hypot(e[0].u_pose, e[1].u_pose)}};
    if (!e[0].plane_keys.empty() && !e[1].plane_keys.empty()) {
        DriftSum d;
        add_plane(d, e[0].plane_frames, e[0].plane_keys, -Eigen::Vector3d::UnitZ());
        add_plane(d, e[1].plane_frames, e[1].plane_keys, Eigen::Vector3d::UnitZ());
        if (const double u = d.u(); u > 0.0) r.u_budget.emplace_back("compensation", u);
        add_holes_term(r.u_budget, d);
    }
    const int planes = (e[0].plane ? 1 : 0) + (e[1].plane ? 1 : 0);
    r.method = planes == 2 ? "planes" : planes == 1 ? "plane and edge" : "edges";
    for (const auto& end : e) {
        r.ends.push_back(end.est);
        if (end.plane) r.fit_rms_mm = std::max(r.fit_rms_mm, end.plane->rms_mm);
    }
    if (planes == 0) edge_sectors(ctx, e, r);
    // Two fitted faces (a forging's ends): what varies around the part shows in the height of
    // each sector both are seen in, as for `method: planes` (two faces' planes: their relative
    // tilt and registration, which the planes' own fits do not see).
    if (!e[0].plane_points.empty() && !e[1].plane_points.empty()) {
        PlaneResult pl[2];
        for (int j = 0; j < 2; ++j) {
            pl[j].fit = *e[j].plane;
            pl[j].points = std::move(e[j].plane_points);  // not needed after
        }
        plane_sectors(ctx, pl, r);
    }
    add_sector_term(r);
}

// Sectors for two planes: the height from the points of each angular sector of both.
void plane_sectors(const Context& ctx, const PlaneResult (&pl)[2], FeatureResult& r) {
    const int ns = std::max(1, ctx.c.sectors);
    std::vector<double> sa(ns, 0), sb(ns, 0);
    std::vector<int> na(ns, 0), nb(ns, 0);
    auto sector = [&](const Eigen::Vector3d& p) {
        const double ang = std::atan2(p.y(), p.x()) + std::numbers::pi;
        return std::min(ns - 1, static_cast<int>(ang / (2 * std::numbers::pi) * ns));
    };
    const PlaneFit& A = pl[0].fit;
    for (const auto& p : pl[0].points) {
        sa[sector(p)] += A.distance(p);
        na[sector(p)]++;
    }
    for (const auto& p : pl[1].points) {
        sb[sector(p)] += A.distance(p);
        nb[sector(p)]++;
    }
    std::vector<double> hs;
    for (int s = 0; s < ns; ++s)
        if (na[s] >= kMinPerSector && nb[s] >= kMinPerSector)
            hs.push_back(std::abs(sb[s] / nb[s] - sa[s] / na[s]));
    r.n_sectors = static_cast<int>(hs.size());
    if (hs.size() >= 2) r.sector_spread_mm = sample_std(hs);
}

// A height within each profile (docs/compensation.md "Heights the vibration cannot move"): the
// head's displacement is one translation per profile, so in each profile that sees both planes
// the mean distance from `ref` of its points on B minus that of its points on A does not contain
// it. The height is their mean, weighted by 1/(1/n_A + 1/n_B); u from strips of consecutive
// profiles (batch means: what stays correlated along the scan, a form or a tilt, averages over
// strips, not over profiles). Nothing when too few profiles see both.
struct PerProfile {
    double value = 0, u_noise = 0;  // the height, its standard error from profile to profile
    std::vector<double> strips;     // the same in kStrips runs of consecutive profiles
    int profiles = 0;
};
constexpr int kMinPerProfile = 3, kMinProfiles = 20, kStrips = 8;
std::optional<PerProfile> per_profile_height(const PlaneResult (&pl)[2], const PlaneFit& ref) {
    std::map<std::int64_t, std::array<std::pair<double, int>, 2>> sums;  // key → (Σ d, n) per plane
    for (int j = 0; j < 2; ++j)
        for (std::size_t q = 0; q < pl[j].points.size(); ++q) {
            auto& [s, n] = sums[pl[j].profile_keys[q]][static_cast<std::size_t>(j)];
            s += ref.distance(pl[j].points[q]);
            ++n;
        }
    std::vector<std::pair<double, double>> d;  // (difference, weight), in profile order
    for (const auto& [key, ab] : sums)
        if (ab[0].second >= kMinPerProfile && ab[1].second >= kMinPerProfile)
            d.emplace_back(ab[1].first / ab[1].second - ab[0].first / ab[0].second,
                           1.0 / (1.0 / ab[0].second + 1.0 / ab[1].second));
    if (static_cast<int>(d.size()) < kMinProfiles) return std::nullopt;
    auto mean = [](auto lo, auto hi) {
        double s = 0, w = 0;
        for (auto it = lo; it != hi; ++it) {
            s += it->first * it->second;
            w += it->second;
        }
        return s / w;
    };
    PerProfile out;
    out.profiles = static_cast<int>(d.size());
    out.value = mean(d.begin(), d.end());
    double s2 = 0, w = 0, w2 = 0;
    for (const auto& [v, wi] : d) {
        s2 += wi * (v - out.value) * (v - out.value);
        w += wi;
        w2 += wi * wi;
    }
    const double n_eff = w * w / w2;  // Kish's effective number of profiles
    out.u_noise = std::sqrt(s2 / w / std::max(1.0, n_eff - 1.0));
    for (int k = 0; k < kStrips; ++k)
        out.strips.push_back(mean(d.begin() + k * out.profiles / kStrips,
                                  d.begin() + (k + 1) * out.profiles / kStrips));
    return out;
}

// `method: planes`: the widest annulus facing the sensors at each level, fitted.
void height_planes(const Context& ctx, const core::FeatureSpec& f,
                   const std::vector<const FaceFrame*>& frames, FeatureResult& r) {
    PlaneResult pl[2];
    const std::string levels[2] = {f.from_level, f.to_level};
    for (int j = 0; j < 2; ++j) {
        std::optional<Annulus> best;
        for (const auto& a : annuli_at(ctx.solid, ctx.level_z(levels[j])))
            if (Context::faces_sensors(a, frames) && (!best || a.hi - a.lo > best->hi - best->lo))
                best = a;
        if (!best) {
            r.reason = "no flat face at level '" + levels[j] + "' facing the sensor";
            return;
        }
        pl[j] = ctx.level_plane(levels[j], *best, frames);
        if (!pl[j].error.empty()) {
            r.reason = pl[j].error;
            return;
        }
    }
    const PlaneFit &A = pl[0].fit, &B = pl[1].fit;
    // Along the normal of the better-supported plane: a narrow or partial annulus (a bore step
    // seen through the bore) has a poorly known tilt, and its centroid sits off the axis.
    const bool a_ref = A.n_points >= B.n_points;
    r.fit_rms_mm = std::max(A.rms_mm, B.rms_mm);
    r.n_points = A.n_points + B.n_points;
    std::vector<std::string> faces;
    for (const auto* fr : frames) faces.push_back(fr->scan->name);
    for (int j = 0; j < 2; ++j)
        r.ends.push_back({levels[j], "plane", faces, pl[j].fit.point.z(),
                          plane_u_at(pl[j], pl[j].fit.point), pl[j].fit.n_points});
    DriftSum d;
    add_plane(d, frames, pl[0].profile_keys, -Eigen::Vector3d::UnitZ());
    add_plane(d, frames, pl[1].profile_keys, Eigen::Vector3d::UnitZ());
    if (const auto pp = per_profile_height(pl, a_ref ? A : B)) {
        r.hot_mm = std::abs(pp->value);
        r.u_budget = {{"fit", pp->u_noise}};
        r.method = "planes, per profile";
        // The holes' term all the same: beside holes a profile's offset moves which of its
        // points the planes keep (2 % loss: Height 2 0.012 mm off, 0.0002 mm uncompensated).
        add_holes_term(r.u_budget, d);
        // The sectors' heights would carry the displacement: strips of profiles instead.
        r.n_sectors = kStrips;
        r.sector_spread_mm = sample_std(pp->strips);
        add_sector_term(r);
        return;
    }
    // Too few profiles see both: one plane's centroid from the other, with the compensation's
    // own error.
    r.hot_mm = a_ref ? std::abs(A.distance(B.point)) : std::abs(B.distance(A.point));
    r.u_budget = {{"fit", std::sqrt(A.rms_mm * A.rms_mm / static_cast<double>(A.n_points) +
                                    B.rms_mm * B.rms_mm / static_cast<double>(B.n_points))}};
    if (const double u = d.u(); u > 0.0) r.u_budget.emplace_back("compensation", u);
    add_holes_term(r.u_budget, d);
    r.method = "planes";
    plane_sectors(ctx, pl, r);
    add_sector_term(r);
}

}  // namespace

// What varies around the part (form, compensation residual, a lean the fit does not see) shows
// in the spread of the sector values: their standard error enters the budget, and u_mm is the
// budget's terms in quadrature.
void add_sector_term(FeatureResult& r) {
    const std::optional<double>& spread =
        r.sector_between_mm ? r.sector_between_mm : r.sector_spread_mm;
    if (spread && r.n_sectors >= 2)
        r.u_budget.push_back({"sectors", *spread / std::sqrt(r.n_sectors)});
    r.u_mm = 0;
    for (const auto& [name, u] : r.u_budget) r.u_mm = std::hypot(r.u_mm, u);
}

void measure_height(const Context& ctx, const core::FeatureSpec& f,
                    const std::vector<const FaceFrame*>& frames, FeatureResult& r) {
    if (f.height_method == core::HeightMethod::kPlanes)
        height_planes(ctx, f, frames, r);
    else
        height_edges(ctx, f, frames, r);
}

}  // namespace hotgauge::measure::detail
