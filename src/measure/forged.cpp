// Diameters of forged edges at the theoretical sharp corner (docs/measurement.md, "Real
// forgings"): the samples of the level's plane, the fillet and the drafted wall near the edge,
// and the corner profile fitted to them about the circle's own centre (corner.cpp).
#include <algorithm>
#include <cmath>
#include <iterator>

#include "corner.hpp"
#include "drift.hpp"
#include "edges.hpp"
#include "feature_kinds.hpp"
#include "frame.hpp"
#include "surfaces.hpp"

namespace hotgauge::measure::detail {

Eigen::Vector2d EdgePlane::axis2d() const {
    const PlaneFit& pl = plane;
    const double z_axis =
        pl.point.z() +
        (pl.normal.x() * pl.point.x() + pl.normal.y() * pl.point.y()) / pl.normal.z();
    return to2d(Eigen::Vector3d(0.0, 0.0, z_axis));
}

namespace {

// Where the corner may be: the window of a sorting gauge and the die shift about the axis.
double corner_slack(const Context& ctx, double R_e) {
    return ctx.ex.tol(ctx.c.edge_window_mm, R_e) * 0.5 + ctx.recipe.forging->die_shift_mm;
}

// Fewer samples than this beyond the plane (fillet and wall): the edge is sharp, or its wall out
// of view, and the edge brackets measure it.
constexpr std::int64_t kMinProfileSamples = 200;
// A fitted fillet smaller than this, or than kSharpRhoNoise times the profile's scatter, is a
// sharp edge: the brackets pin it better than the profile. Within a few σ of the range noise a
// fillet cannot be told from the noise below a sharp edge's plane (an ideal part at σ 0.1 mm:
// a "fillet" of 0.3-0.4 mm fitted to it put the corner 0.13 mm out).
constexpr double kSharpRhoMm = 0.1, kSharpRhoNoise = 5.0;
// CornerPoint::profile: face index × this + profile.
constexpr std::int64_t kProfileKeyFace = 1'000'000;
// CornerPoint::sample: face index × this + the sample's index in the face's grid.
constexpr std::int64_t kSampleKeyFace = 1'000'000'000'000;
// Fewer wall samples than this do not fix the wall's draft.
constexpr std::int64_t kMinWallSamples = 150;
// The profile's samples scatter by the range noise (0.05 mm); far more is not this corner.
constexpr double kMaxRmsMm = 0.2;
// The wall's plain cone ends this far clear of its other end's fillet, or of the parting plane
// (docs/measurement.md, "Real forgings"; the margins not measured).
constexpr double kClearOfFilletMm = 0.5, kClearOfPartingMm = 1.0;
// A short step: its other level within two of this edge's fillets and this (docs/measurement.md:
// hub-a's recess, 5 mm, and spigot nose, 8 mm, are in).
constexpr double kShortStepExtraMm = 4.0;
// The far level must be this much wider than its fillet to be seen past it (not measured).
constexpr double kFarFlatMm = 1.0;
// The z band gathered around the window's ends before h and s select in it (not measured).
constexpr double kGatherMarginMm = 1.0;
// The window reaches this far beyond the wall's foot at the drawing's steepest draft, and the
// far level's samples this far below it (not measured).
constexpr double kBeyondWallMm = 0.5, kBelowStepMm = 0.5;
// A fit is refused past the drawing by more than 1° of draft or 20 % + 0.2 mm of fillet (not
// measured), or off the axis by more than twice the window (docs/measurement.md, "Refused").
constexpr double kDraftSlackDeg = 1.0, kFilletSlackFactor = 1.2, kFilletSlackMm = 0.2;
constexpr double kOffAxisWindows = 2.0;
// A short step's far level in the window: 1.5 mm of it, and 4 mm for the `model` term
// (docs/measurement.md, "A short step's two fillets").
constexpr double kFarLevelNearMm = 1.5, kFarLevelWideMm = 4.0;
// The plane faces' corner window inside the circle: past the drawing's fillet by this on the
// first pass (with the sorting gauge's window), then ±1.5 mm around the fitted fillet
// (docs/measurement.md, "Real forgings").
constexpr double kFirstPassInMm = 1.0, kSecondPassInMm = 1.5;
// The die shift: one half's axis must span this to fix the halves' common direction
// (docs/measurement.md, "Die shift"), and u² is floored at this in the 1/u² weights so that no
// circle takes all the weight (not measured).
constexpr double kMinAxisSpanMm = 5.0, kMinCentreU2Mm2 = 1e-8;

// How far down the wall (hot, mm from the level) is plain cone: to the section's other level's
// fillet, or to the parting plane, where the drafts change direction and the die shift steps.
double wall_depth(const Context& ctx, const core::FeatureSpec& f) {
    const core::Section* s = ctx.recipe.section(f.section);
    const std::string& other = f.edge_at == s->from_level ? s->to_level : s->from_level;
    const double z_e = ctx.level_z(f.edge_at);
    double z_o = ctx.level_z(other), stop = ctx.recipe.fillet_at(other) + kClearOfFilletMm;
    const double zp = ctx.recipe.forging->parting_z_mm;
    if ((zp - z_e) * (zp - z_o) < 0.0) {
        z_o = zp;
        stop = kClearOfPartingMm;
    }
    return std::max(0.0, std::abs(z_o - z_e) - stop) * ctx.ex.g;
}

// A short step (hub-a's recess, 5 mm): its wall ends in the section's other level, facing the
// same sensor, beyond the wall, so close that the two fillets may hide the wall. Its nominal
// depth (hot, mm) when it is one, else 0: the far corner then enters the corner's model.
double step_depth(const Context& ctx, const core::FeatureSpec& f, double side) {
    const core::Section* s = ctx.recipe.section(f.section);
    const std::string& other = f.edge_at == s->from_level ? s->to_level : s->from_level;
    const double R = 0.5 * s->diameter_mm, rho_max = ctx.recipe.fillet_at(f.edge_at);
    const double z_e = ctx.level_z(f.edge_at), z_o = ctx.level_z(other);
    const double zp = ctx.recipe.forging->parting_z_mm;
    const double D = std::abs(z_o - z_e);
    if ((zp - z_e) * (zp - z_o) < 0.0 || D > 2.0 * rho_max + kShortStepExtraMm) return 0.0;
    // This level's face runs inside the corner circle, the other's beyond it, both facing alike
    // and the other wide enough to be seen past its fillet.
    const auto face_at = [&](double z, bool beyond) -> std::optional<Annulus> {
        for (const Annulus& a : annuli_at(ctx.solid, z))
            if ((side > 0) == beyond ? a.lo == R : a.hi == R) return a;
        return std::nullopt;
    };
    const auto here = face_at(z_e, false), there = face_at(z_o, true);
    if (!here || !there || here->facing != there->facing ||
        there->hi - there->lo < ctx.recipe.fillet_at(other) + kFarFlatMm)
        return 0.0;
    return D * ctx.ex.g;
}

// The samples near the corner circle (c, R) in the plane's frame: h in [−depth, 0.5], s (beyond
// the circle) in [−s_in, s_out].
std::vector<CornerPoint> corner_points(const std::vector<const FaceFrame*>& frames,
                                       const EdgePlane& ep, double side, const Eigen::Vector2d& c,
                                       double R, double s_in, double s_out, double depth) {
    constexpr double kAbove = 0.5;
    const double nz = std::abs(ep.plane.normal.z()), z0 = ep.plane.point.z();
    const double up = ep.plane.normal.z() > 0 ? 1.0 : -1.0;
    const double za = z0 - up * depth * nz, zb = z0 + up * kAbove;
    const double z_from = std::min(za, zb) - kGatherMarginMm,
                 z_to = std::max(za, zb) + kGatherMarginMm;
    // A cheap bound first, on the sample's distance r from the part axis: the slab holds the
    // whole level, the window a ring of it. In the plane, a sample's distance from the axis's
    // crossing a2 differs from r by at most (|h| + r·sin θ) / cos θ (θ the plane's tilt, h the
    // sample's height over it), and its distance from c by |c − a2| more.
    const double sin_t = std::sqrt(std::max(0.0, 1.0 - nz * nz));
    const double h_max = std::max(depth, kAbove), c_off = (c - ep.axis2d()).norm();
    const double lo = side > 0 ? R - s_in : R - s_out, hi = side > 0 ? R + s_out : R + s_in;
    constexpr double kRoundingMm = 1e-3;  // r is a float
    // A corner whose numbers are not finite (a fit gone wrong): no bound, the full test decides.
    const bool bounded = std::isfinite(c_off) && std::isfinite(lo) && std::isfinite(hi);
    auto maybe_in = [&](double r) {
        const double e = c_off + (h_max + r * sin_t) / nz + kRoundingMm;
        return !bounded || (r + e >= lo && r - e <= hi);
    };
    std::vector<CornerPoint> out;
    for (std::size_t face = 0; face < frames.size(); ++face) {
        const FaceFrame* fr = frames[face];
        fr->for_z(z_from, z_to, [&](const FaceFrame::Near& n) {
            if (!maybe_in(n.r)) return;
            const Eigen::Vector3d p = n.p.cast<double>();
            const double h = ep.plane.distance(p);
            if (h < -depth || h > kAbove) return;
            const Eigen::Vector2d q = ep.to2d(p);
            const double s = side * ((q - c).norm() - R);
            if (s < -s_in || s > s_out) return;
            // The ray towards the sensor: its part away from the axis, and along h.
            const Eigen::Vector3d ray = -fr->ray_dir(n.q % fr->w).normalized();
            const Eigen::Vector2d radial = (q - c).norm() > 1e-9
                                               ? Eigen::Vector2d((q - c).normalized())
                                               : Eigen::Vector2d::UnitX();
            const Eigen::Vector2d in_plane(ray.dot(ep.e1), ray.dot(ep.e2));
            const auto profile = static_cast<std::int64_t>(n.q / fr->w + face * kProfileKeyFace);
            const auto sample = static_cast<std::int64_t>(n.q + face * kSampleKeyFace);
            out.push_back(
                {q, h, {in_plane.dot(radial), ray.dot(ep.plane.normal)}, profile, sample});
        });
    }
    return out;
}

// A fillet is seen when its samples, per mm of its width across the plane, are at least a third
// as dense as the plane's: a few hundred samples strewn over a sharp edge's shadow are not one.
bool fillet_seen(const CornerFit& fit, double s_in) {
    constexpr double kMinDensityRatio = 0.3;
    // Floors on the widths the densities are taken over (not measured).
    constexpr double kMinArcWidthMm = 0.05, kMinPlaneWidthMm = 0.5;
    const double arc_width = std::max(fit.m.rho, kMinArcWidthMm);
    const double plane_width = std::max(s_in - arc_width, kMinPlaneWidthMm);
    return static_cast<double>(fit.n_arc + fit.n_wall) / arc_width >=
           kMinDensityRatio * static_cast<double>(fit.n_plane) / plane_width;
}

// Why a fitted profile is not this corner's (a wrong pose, another surface in the window, a
// shadow), or empty: far more scatter than the range noise, a circle its samples do not fix, a
// fillet or draft the drawing does not allow, a circle off where the part can have it.
std::string refusal(const CornerFit& fit, const CornerPrior& prior, double R_e, double slack,
                    const Eigen::Vector2d& axis) {
    const CornerModel& m = fit.m;
    if (fit.rms > kMaxRmsMm)
        return "its samples lie " + std::to_string(fit.rms) +
               " mm RMS off the corner's profile: wrong pose or wrong part";
    if (!std::isfinite(fit.u_radius)) return "its samples do not fix the corner's circle";
    const double t_limit = std::tan(std::atan(prior.t_max) + kDraftSlackDeg / kRadToDeg);
    if (m.rho > kFilletSlackFactor * prior.rho_max + kFilletSlackMm || m.t > t_limit)
        return "fitted fillet R " + std::to_string(m.rho) + " mm, draft " +
               std::to_string(std::atan(m.t) * kRadToDeg) +
               "°, outside the drawing's (R <= " + std::to_string(prior.rho_max) + " mm)";
    if (std::abs(m.radius - R_e) > kOffAxisWindows * slack ||
        (m.centre - axis).norm() > kOffAxisWindows * slack)
        return "fitted at radius " + std::to_string(m.radius) + " mm, " +
               std::to_string((m.centre - axis).norm()) +
               " mm off the part axis: wrong pose or wrong part";
    return {};
}

// The wall's draft from faces that see it broadside (side scans): the slope of its samples'
// distance beyond the corner circle against their height, between the fillets. Only the slope is
// taken from them, so their registration against the plane's faces does not enter: an offset
// of a face moves s, not ds/dh. Nothing when they see too little of it.
struct Draft {
    double t, u;
};
std::optional<Draft> wall_draft(const std::vector<const FaceFrame*>& wall_frames,
                                const EdgePlane& ep, double side, const CornerModel& m,
                                double depth, double t_max) {
    constexpr std::size_t kMinSamples = 200;
    constexpr double kMinSpanMm = 2.0, kBandMm = 0.5;
    // The straight part starts this far below the fillet; rounds of fit and 3σ rejection, with a
    // floor on the rejection distance (not measured).
    constexpr double kBelowFilletMm = 0.5, kRejectK = 3.0, kRejectFloorMm = 0.02;
    constexpr int kRounds = 3;
    const double h_top = -(m.rho + kBelowFilletMm), h_bottom = -depth;
    if (wall_frames.empty() || h_top - h_bottom < kMinSpanMm) return std::nullopt;
    const auto pts = corner_points(wall_frames, ep, side, m.centre, m.radius, kBandMm,
                                   kBandMm + t_max * depth, depth);
    std::vector<Eigen::Vector2d> sh;  // (h, s) on the wall's straight part
    for (const auto& p : pts)
        if (p.h <= h_top) sh.emplace_back(p.h, side * ((p.q - m.centre).norm() - m.radius));
    for (int round = 0; round < kRounds; ++round) {
        if (sh.size() < kMinSamples) return std::nullopt;
        Eigen::Matrix2d A = Eigen::Matrix2d::Zero();
        Eigen::Vector2d b = Eigen::Vector2d::Zero();
        for (const auto& v : sh) {
            const Eigen::Vector2d row(1.0, v.x());
            A += row * row.transpose();
            b += row * v.y();
        }
        const Eigen::Vector2d k = A.ldlt().solve(b);
        double sse = 0;
        for (const auto& v : sh) sse += std::pow(v.y() - k[0] - k[1] * v.x(), 2);
        const double sigma = std::sqrt(sse / static_cast<double>(sh.size() - 2));
        if (round == kRounds - 1) return Draft{-k[1], sigma * std::sqrt(A.inverse()(1, 1))};
        std::erase_if(sh, [&](const Eigen::Vector2d& v) {
            return std::abs(v.y() - k[0] - k[1] * v.x()) >
                   std::max(kRejectK * sigma, kRejectFloorMm);
        });
    }
    return std::nullopt;
}

// The compensation's own error in the diameter: twice the mean, over the fillet's and the wall's
// inliers, of their displacement error away from the centre (CornerFit::radial).
DriftSum drift(const std::vector<const FaceFrame*>& frames, const EdgePlane& ep,
               const CornerFit& fit) {
    const auto n = static_cast<double>(fit.n_arc + fit.n_wall);
    DriftSum d;
    if (n <= 0.0) return d;
    for (const auto& [key, sum] : fit.radial) {
        const auto face = static_cast<std::size_t>(key / kProfileKeyFace);
        if (key < 0 || face >= frames.size()) continue;
        add_radial(d, *frames[face], key % kProfileKeyFace, sum, ep.e1, ep.e2, n);
    }
    return d;
}

}  // namespace

// The corner of a wall the plane's faces see too little to fix its draft (top and bottom
// sensors lose a 1-3° wall at grazing incidence), from their last free fit. Its draft is held at
// the slope the side faces see, when they see the wall; else, on a short step whose far corner
// is seen, the wall is the common tangent of its two fillets, which fix its draft; else the draft
// is held at the drawing's middle. What a held draft may be off goes into u. The fit at the
// drawing's middle is kept in `memo`, and a side draft refits from it (refit_draft): the last
// side scan costs a few steps per diameter, and the value does not depend on which side scans
// were in when the corner was first fitted.
CornerFit fit_hidden_wall(const std::vector<const FaceFrame*>& frames,
                          const std::vector<const FaceFrame*>& wall_frames, const EdgePlane& ep,
                          double side, CornerMemo& memo, CornerPrior& prior) {
    const CornerModel& m = memo.start;
    const double depth = memo.depth, step = memo.step;
    const auto d = wall_draft(wall_frames, ep, side, m, depth, prior.t_max);
    if (!d && step > 0.0) {
        // The far fillet and 1.5 mm of the far level in the window; again with 4 mm, for how
        // much the result leans on the model's shape. One gathering, the first a part of it.
        const double s_far = prior.t_max * step + prior.rho_max;
        const auto wide = corner_points(frames, ep, side, m.centre, m.radius, memo.s_in,
                                        s_far + kFarLevelWideMm, step + kBelowStepMm);
        std::vector<CornerPoint> near;
        std::copy_if(wide.begin(), wide.end(), std::back_inserter(near), [&](const CornerPoint& p) {
            return side * ((p.q - m.centre).norm() - m.radius) <= s_far + kFarLevelNearMm;
        });
        prior.depth = step;
        CornerFit far = fit_corner(near, side, m, prior);
        if (far.n_far >= kMinProfileSamples) {
            const CornerFit f = fit_corner(wide, side, m, prior, false);
            if (f.n_far >= kMinProfileSamples) {
                far.u_model = std::abs(f.m.radius - far.m.radius);
                // The same samples with the orthogonal distance: how much the steep fillets'
                // weighting moves the corner, which two fillets far apart amplify.
                for (auto& p : near) p.ray.setZero();
                const CornerFit o = fit_corner(near, side, far.m, prior, false);
                far.u_estimator = std::abs(o.m.radius - far.m.radius);
                return far;
            }
        }
        prior.depth = 0.0;
    }
    prior.fix_draft = true;
    if (!memo.held) {  // at the drawing's draft: the same start whichever wall faces are in
        memo.held_pts = corner_points(frames, ep, side, m.centre, m.radius, memo.s_in,
                                      kBeyondWallMm + prior.t_max * depth, depth);
        memo.held =
            fit_corner(memo.held_pts, side, {m.centre, m.radius, prior.t_mean(), m.rho}, prior);
    }
    if (!d) return *memo.held;
    prior.t_known = d->t;
    prior.t_known_u = d->u;
    return refit_draft(memo.held_pts, side, *memo.held, prior);
}

// The corner's free fit on its plane's faces (they see the plane, the fillet and perhaps the
// wall): wide around the expected circle, then tight around the fitted one. Nothing beyond the
// plane, or a sharp edge: `brackets`, for the edge brackets. A wall they do not see is left to
// fit_hidden_wall, once the faces that may see it are in.
CornerMemo plane_faces_corner(const Context& ctx, const core::FeatureSpec& f,
                              const std::vector<const FaceFrame*>& frames, const EdgePlane& ep,
                              double side) {
    CornerMemo out;
    out.fitted = true;
    CornerPrior& prior = out.prior;
    prior = {std::tan(ctx.recipe.draft_of(f.section) / kRadToDeg), ctx.recipe.fillet_at(f.edge_at)};
    out.step = step_depth(ctx, f, side);
    out.depth = wall_depth(ctx, f);
    const double R_e = ctx.ex.z(0.5 * ctx.recipe.section(f.section)->diameter_mm);
    const double slack = corner_slack(ctx, R_e);
    CornerModel m{ep.axis2d(), R_e, 0.5 * prior.t_max, 0.5 * prior.rho_max};
    std::vector<CornerPoint> pts;
    for (int pass = 0; pass < 2; ++pass) {
        out.s_in = pass == 0 ? prior.rho_max + kFirstPassInMm + slack : m.rho + kSecondPassInMm;
        const double s_beyond = pass == 0 ? slack : 0.0;
        pts = corner_points(frames, ep, side, m.centre, m.radius, out.s_in,
                            s_beyond + kBeyondWallMm + prior.t_max * out.depth, out.depth);
        // Nothing beyond the plane (a sharp edge over a wall no sensor of the plane sees: every
        // edge of an ideal part): the edge brackets, without a profile fit that would say so.
        out.brackets = pass == 0 && std::count_if(pts.begin(), pts.end(), [](const CornerPoint& p) {
                                        return p.beyond_plane();
                                    }) < kMinProfileSamples;
        if (out.brackets) return out;
        out.fit = fit_corner(pts, side, {m.centre, m.radius, m.t, m.rho}, prior, false);
        // Sharp, or nothing beyond the plane: the edge brackets (decided on the free fit).
        out.brackets = out.fit.n_arc + out.fit.n_wall < kMinProfileSamples ||
                       !fillet_seen(out.fit, out.s_in) ||
                       out.fit.m.rho < std::max(kSharpRhoMm, kSharpRhoNoise * out.fit.rms);
        if (out.brackets) return out;
        m = out.fit.m;
    }
    out.start = m;
    out.wall_unseen = out.fit.n_wall < kMinWallSamples;
    // Its own wall seen: the free fit is the corner, with the jackknife's u (from the solution,
    // the fit takes a step or two).
    if (!out.wall_unseen) out.fit = fit_corner(pts, side, m, prior);
    return out;
}

bool corner_diameter(const Context& ctx, const core::FeatureSpec& f,
                     const std::vector<const FaceFrame*>& frames,
                     const std::vector<const FaceFrame*>& wall_frames, const EdgePlane& ep,
                     double side, FeatureResult& r, CornerMemo& memo) {
    if (!memo.fitted) memo = plane_faces_corner(ctx, f, frames, ep, side);
    if (memo.brackets) return false;
    const double R_e = ctx.ex.z(0.5 * ctx.recipe.section(f.section)->diameter_mm);
    const double slack = corner_slack(ctx, R_e);
    CornerPrior prior = memo.prior;
    r.wall_faces_used = memo.wall_unseen;
    const CornerFit fit =
        memo.wall_unseen ? fit_hidden_wall(frames, wall_frames, ep, side, memo, prior) : memo.fit;
    const CornerModel& m = fit.m;
    if (const std::string why = refusal(fit, prior, R_e, slack, ep.axis2d()); !why.empty()) {
        r.reason = "corner of '" + f.section + "' at '" + f.edge_at + "': " + why;
        return true;
    }
    r.hot_mm = 2.0 * m.radius;
    const DriftSum d = drift(frames, ep, fit);
    r.u_budget = {{"fit", 2.0 * fit.u_radius},
                  {"compensation", std::hypot(ep.profile_scatter, d.u())}};
    add_holes_term(r.u_budget, d);
    if (fit.u_model > 0.0) r.u_budget.emplace_back("model", 2.0 * fit.u_model);
    if (fit.u_estimator > 0.0) r.u_budget.emplace_back("estimator", 2.0 * fit.u_estimator);

    r.fit_rms_mm = fit.rms;
    r.n_points = fit.n_arc + fit.n_wall;
    // The draft's own uncertainty is in the fit's (the prior's row of the normal matrix).
    r.method = prior.depth > 0.0  ? "corner profile, draft from the step's two fillets"
               : !prior.fix_draft ? "corner profile"
               : prior.t_known    ? "corner profile, draft from the side faces"
                                  : "corner profile, draft from the drawing";
    r.arc_deg = 45.0 * static_cast<double>(fit.sector_radius.size());
    r.n_sectors = static_cast<int>(fit.sector_radius.size());
    if (fit.sector_radius.size() >= 2) r.sector_spread_mm = 2.0 * sample_std(fit.sector_radius);
    add_sector_term(r);
    r.ends.push_back({f.edge_at, "corner profile", f.faces, m.radius, 0.5 * r.u_mm, r.n_points});
    r.centre_mm = ep.plane.point + m.centre.x() * ep.e1 + m.centre.y() * ep.e2;
    return true;
}

}  // namespace hotgauge::measure::detail

namespace hotgauge::measure::detail {

// The two halves' axes share one direction (a die shift is a translation): x = a_half + b·z,
// y = c_half + d·z by weighted least squares over the measured circles' centres; the die shift
// is the distance between the halves' axes, the same at every z.
void measure_die_shift(const Context& ctx, const std::vector<FeatureResult>& measured,
                       FeatureResult& r) {
    const double zp = ctx.ex.z(ctx.recipe.forging->parting_z_mm);
    Eigen::Matrix3d A[2];  // per coordinate: unknowns (upper offset, lower offset, slope)
    Eigen::Vector3d b[2];
    for (int k = 0; k < 2; ++k) A[k].setZero(), b[k].setZero();
    int n[2] = {0, 0};
    double z_lo[2] = {1e300, 1e300}, z_hi[2] = {-1e300, -1e300};
    for (const auto& f : measured) {
        if (f.kind != core::FeatureKind::kDiameter || !f.hot_mm || !f.centre_mm) continue;
        const Eigen::Vector3d& c = *f.centre_mm;
        const int half = c.z() > zp ? 0 : 1;
        const double w = 1.0 / std::max(f.u_mm * f.u_mm, kMinCentreU2Mm2);
        Eigen::Vector3d row = Eigen::Vector3d::Zero();
        row[half] = 1.0;
        row[2] = c.z();
        for (int k = 0; k < 2; ++k) {
            A[k] += w * row * row.transpose();
            b[k] += w * row * c[k];
        }
        n[half]++;
        z_lo[half] = std::min(z_lo[half], c.z());
        z_hi[half] = std::max(z_hi[half], c.z());
    }
    if (n[0] < 1 || n[1] < 1 || std::max(z_hi[0] - z_lo[0], z_hi[1] - z_lo[1]) < kMinAxisSpanMm) {
        r.reason = "die shift: needs measured circles on both halves (upper " +
                   std::to_string(n[0]) + ", lower " + std::to_string(n[1]) +
                   ") and 5 mm of axis within one half";
        return;
    }
    Eigen::Vector2d shift, u2;
    for (int k = 0; k < 2; ++k) {
        const Eigen::Vector3d x = A[k].ldlt().solve(b[k]);
        const Eigen::Matrix3d cov = A[k].inverse();
        shift[k] = x[0] - x[1];
        u2[k] = cov(0, 0) + cov(1, 1) - 2.0 * cov(0, 1);
    }
    r.hot_mm = shift.norm();
    const Eigen::Vector2d dir =
        shift.norm() > 1e-9 ? Eigen::Vector2d(shift / shift.norm()) : Eigen::Vector2d(1.0, 0.0);
    r.u_budget = {{"centres", std::sqrt(dir.x() * dir.x() * u2.x() + dir.y() * dir.y() * u2.y())}};
    r.n_points = 0;
    std::string degraded;  // a circle the data cannot vouch for: neither can the die shift
    for (const auto& f : measured)
        if (f.kind == core::FeatureKind::kDiameter && f.hot_mm && f.centre_mm) {
            r.n_points += f.n_points;
            if (!f.degraded) continue;
            degraded += (degraded.empty() ? "" : ", ") + f.name;
            for (const auto& run : f.left_out)
                if (std::find(r.left_out.begin(), r.left_out.end(), run) == r.left_out.end())
                    r.left_out.push_back(run);
        }
    if (!degraded.empty()) {
        r.degraded = true;
        r.degraded_because = "from circles measured with untrusted profiles (" + degraded + ")";
    }
    r.method = "circle centres";
    add_sector_term(r);
}

}  // namespace hotgauge::measure::detail
