#pragma once
// The theoretical sharp corner of a forged edge (docs/measurement.md, "Real forgings"): the
// level's plane, the wall's cone and the fillet between them, fitted as one profile about the
// circle's own centre. Internal to the measure module.
#include <Eigen/Core>
#include <optional>
#include <string>
#include <vector>

#include "hotgauge/core/part.hpp"
#include "hotgauge/measure/features.hpp"
#include "hotgauge/measure/fit.hpp"

namespace hotgauge::measure::detail {

struct Context;
struct FaceFrame;

// A level's plane with its normal towards the sensor (out of the material), its on-plane
// threshold, the profiles' scatter off it, and a 2D frame in it for circle fits.
struct EdgePlane {
    PlaneFit plane;
    double thr = 0;
    double profile_scatter = 0;
    Eigen::Vector3d e1, e2;
    Eigen::Vector2d to2d(const Eigen::Vector3d& p) const {
        const Eigen::Vector3d d = p - plane.point;
        return {d.dot(e1), d.dot(e2)};
    }
    // Where the part axis crosses the plane, in its 2D frame.
    Eigen::Vector2d axis2d() const;
};

// Below the plane by more than 3σ of the range noise: beyond it (a fillet's or a wall's sample).
constexpr double kBeyondPlaneMm = 0.15;

// A sample in the level plane's frame: q its in-plane coordinates, h its height above the plane
// (positive out of the material, towards the sensor that sees the plane), and its ray towards the
// sensor: (component away from the axis, component along h); (0, 0): unknown, the residual is
// the distance along the profile's normal.
struct CornerPoint {
    Eigen::Vector2d q;
    double h;
    Eigen::Vector2d ray = Eigen::Vector2d::Zero();
    // The profile it was seen in (unique over the faces), or −1: samples of one profile share
    // its vibration residual, which u must count once per profile, not once per sample.
    std::int64_t profile = -1;
    // The sample itself (unique over the faces), or −1: the fit's thinning keeps a sample by it,
    // not by the sample's place in a window's list.
    std::int64_t sample = -1;
    bool beyond_plane() const { return h < -kBeyondPlaneMm; }
};

// The corner's profile in the half-plane (s, h) about `centre`: s = side·(r − radius) is how far
// a point lies beyond the corner circle (side +1 for an outer edge, −1 for a bore). The plane
// h = 0 runs up to the fillet, an arc of radius `rho` tangent to both, the wall s = −t·h below
// it (t = tan draft ≥ 0: a drafted wall always opens the corner). rho = 0 and t = 0 is the
// drawing's idealisation.
struct CornerModel {
    Eigen::Vector2d centre = Eigen::Vector2d::Zero();
    double radius = 0;  // the theoretical sharp corner: where the wall meets the plane
    double t = 0;
    double rho = 0;
    // A short step (the recess, 5 mm deep): the wall ends a depth below in the step's other
    // level, h = −depth, beyond the wall, through a concave fillet of radius rho2. Its wall may
    // be too short to be seen at all; the two fillets, both tangent to it, then fix its draft.
    // depth 0: no far corner in the model (the wall runs on out of the samples' window).
    double depth = 0;
    double rho2 = 0;
};

struct CornerPrior {
    double t_max = 0;    // tan of the drawing's largest draft
    double rho_max = 0;  // the drawing's largest fillet radius
    // The wall is out of view: the draft is held (at t_known, else the middle of the drawing's
    // range), and its uncertainty t_sigma enters u_radius.
    bool fix_draft = false;
    // A draft measured elsewhere (the wall seen broadside by another face): held there instead.
    std::optional<double> t_known = std::nullopt, t_known_u = std::nullopt;
    // A short step's nominal depth to its far level (a far corner in the model), or 0.
    double depth = 0;
    double t_mean() const { return t_known ? *t_known : 0.5 * t_max; }
    double t_sigma() const;  // the drawing's range / √12, or the measured draft's u
};

struct CornerFit {
    CornerModel m;
    // Standard uncertainty of `radius`: σ²·(JᵀJ)⁻¹ (priors included), or, when larger, the
    // jackknife's over groups of profiles.
    double u_radius = 0;
    double u_jackknife = 0;  // the jackknife's share of it (0: not run)
    // What the radius moves by when the model's window moves (a far corner: the far level taken
    // 1.5 or 4 mm beyond its fillet): its shape is not quite the drawing's. 0 when not tried.
    double u_model = 0;
    // What the radius moves by with the orthogonal distance instead of the distance along the
    // ray (a step's two fillets: the steep parts' weighting). 0 when not tried.
    double u_estimator = 0;
    double rms = 0;
    std::int64_t n_wall = 0, n_arc = 0, n_plane = 0;  // inliers by the part of the profile
    std::int64_t n_far = 0;                           // on the far fillet and the far level
    std::vector<double> sector_radius;                // the radius from each sector's points
    // Per profile (CornerPoint::profile), the sum of the unit vectors away from the centre of
    // its fillet and wall inliers: how a shift of that profile moves the radius (drift.hpp).
    // Only on a fit whose u is reported (fit_corner with the jackknife, refit_draft).
    std::vector<std::pair<std::int64_t, Eigen::Vector2d>> radial;
};

// Least squares (Levenberg–Marquardt, 3σ rejection) of the corner profile to the samples. The
// draft has a weak prior (the middle of the drawing's range, ± the range/√12), so a wall seen
// too little to fix its own draft costs uncertainty rather than a value. `side`: +1 outer, −1
// bore. u_radius is infinite when the samples do not fix the model. `jackknife`: u_radius also
// from the jackknife over groups of profiles (four more solves); a fit whose u is not reported
// (a first pass, a probe of the window) goes without.
CornerFit fit_corner(const std::vector<CornerPoint>& pts, double side, const CornerModel& start,
                     const CornerPrior& prior, bool jackknife = true);

// `held` (a fit of `pts` with its draft held) again with the draft `prior` holds: from its
// solution and on its inliers, one solve (a few steps: the draft moves the corner by tens of
// micrometres). Its u keeps `held`'s jackknife. The daemon's last face, which brings a side
// scan's draft, costs this instead of a whole fit (PartMeasurer, docs/measurement.md "In two
// steps").
CornerFit refit_draft(const std::vector<CornerPoint>& pts, double side, const CornerFit& held,
                      const CornerPrior& prior);

// The distance of a sample from the profile, and where it lies (0 plane, 1 fillet, 2 wall, 3 far
// fillet, 4 far level).
double corner_residual(const CornerModel& m, double side, const CornerPoint& p, int* part);

// A corner as its plane's faces give it, kept while the faces that see its wall come in (the
// daemon measures a diameter as soon as its first face is in: PartMeasurer), so that they cost
// only the refit with their draft. Valid for one set of plane faces.
struct CornerMemo {
    bool fitted = false;    // the plane's faces were fitted
    bool brackets = false;  // nothing beyond the plane, or a sharp edge: the edge brackets
    CornerFit fit;          // the free fit, the corner when its wall was seen
    CornerPrior prior;
    // The wall out of the plane's faces' view: the corner refitted from `start` (the last free
    // fit, no far corner) with a held draft, in the last pass's window (s_in inside the circle,
    // depth down the wall; step: a short step's depth).
    bool wall_unseen = false;
    CornerModel start;
    double s_in = 0, depth = 0, step = 0;
    // ... and so refitted at the drawing's draft, with its samples: what a draft from the wall's
    // faces starts from (refit_draft), whichever of them are in.
    std::optional<CornerFit> held;
    std::vector<CornerPoint> held_pts;
};

// Diameter `f` at its theoretical sharp corner when its edge is filleted or its wall seen: the
// corner profile fitted on the samples of its plane, fillet and wall (recipes with a forging
// drawing). Returns false, leaving `r` as it was, when nothing beyond the plane is seen (a sharp
// edge over a wall out of view): the edge brackets measure that corner. `side`: +1 outer edge.
// `wall_frames`: faces that see the wall broadside but not the plane (side scans), for the draft
// when the plane's faces do not see the wall. `memo`: what `frames` gave, computed when empty.
bool corner_diameter(const Context& ctx, const core::FeatureSpec& f,
                     const std::vector<const FaceFrame*>& frames,
                     const std::vector<const FaceFrame*>& wall_frames, const EdgePlane& ep,
                     double side, FeatureResult& r, CornerMemo& memo);

}  // namespace hotgauge::measure::detail
