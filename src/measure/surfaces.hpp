#pragma once
// Flat faces of the part (docs/measurement.md, "Planes"): which annuli the recipe's solid has at a
// level, and the robust plane of one from the scans. What every feature kind shares: the recipe,
// its solid, the expected hot geometry and the settings (`Context`). Internal to the module.
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <tuple>
#include <vector>

#include "frame.hpp"
#include "hotgauge/core/part.hpp"
#include "hotgauge/measure/features.hpp"
#include "hotgauge/measure/fit.hpp"

namespace hotgauge::measure::detail {

constexpr double kRadToDeg = 57.295779513082320876798;

// A sample is on a fitted surface within k·rms, never tighter than on_surface_min_mm.
double surface_threshold(double rms, const MeasureConfig& c);

// Horizontal boundary pieces of the nominal solid at z, merged into contiguous r-intervals,
// with their outward normal (+1: material below, facing +z).
struct Annulus {
    double lo, hi;
    int facing;
};
std::vector<Annulus> annuli_at(const core::AxisymmetricSolid& s, double z);

struct PlaneResult {
    PlaneFit fit;
    std::vector<Eigen::Vector3d> points;     // inliers
    std::vector<std::int64_t> profile_keys;  // per inlier: face index << 32 | profile
    std::string error;
};
// Least-squares plane of the annulus [r_lo, r_hi] at hot height z_e (±band), from all given
// faces: RANSAC seed, then iterative 3σ rejection. `what` names it in errors.
PlaneResult fit_level_plane(const std::vector<const FaceFrame*>& frames, double z_e, double band,
                            double r_lo, double r_hi, const MeasureConfig& c,
                            const std::string& what);

// How far whole profiles sit off the fitted plane beyond what the range noise explains: the
// residual of the vibration compensation along the plane's normal (docs/measurement.md,
// "Uncertainty"). From the mean residual of each profile with ≥ 20 points on the plane.
double profile_scatter(const PlaneResult& pl);

// The level planes fitted so far, so that features sharing a level fit it once (hub-a: 19 fits of
// 7 planes per part). Keyed by the level, the annulus and the faces' addresses, so it is cleared
// whenever faces are added or replaced (PartMeasurer::add_faces). Features are measured in
// parallel: a fit two of them ask for at once is made twice, with the same result.
struct PlaneMemo {
    using Key = std::tuple<std::string, double, double, int, std::vector<const FaceFrame*>>;
    std::mutex mutex;
    std::map<Key, struct PlaneResult> planes;
    void clear() {
        std::lock_guard lock(mutex);
        planes.clear();
    }
};

struct Context {
    const core::Recipe& recipe;
    core::AxisymmetricSolid solid;
    Expect ex;
    MeasureConfig c;
    std::shared_ptr<PlaneMemo> memo = std::make_shared<PlaneMemo>();

    double level_z(const std::string& level) const { return *recipe.level(level); }
    // The annulus faces every face's sensor: its outward normal points against each view.
    static bool faces_sensors(const Annulus& a, const std::vector<const FaceFrame*>& frames);
    // The annulus at `level` next to radius R (nominal, cold) that faces the sensors, or why not.
    std::optional<Annulus> annulus(const std::string& level, double R,
                                   const std::vector<const FaceFrame*>& frames,
                                   std::string& why) const;
    // The plane of annulus `a` at `level` (hot), 0.6 mm clear of its ends; refused when tilted
    // more than max_plane_tilt_deg from the part axis.
    PlaneResult level_plane(const std::string& level, const Annulus& a,
                            const std::vector<const FaceFrame*>& frames) const;

  private:
    PlaneResult fit_annulus_plane(const std::string& level, const Annulus& a,
                                  const std::vector<const FaceFrame*>& frames) const;
};

}  // namespace hotgauge::measure::detail
