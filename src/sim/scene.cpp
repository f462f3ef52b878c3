#include "hotgauge/sim/scene.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <optional>

namespace hotgauge::sim {
namespace {

constexpr double kG = 9.81;  // m/s², as recording-format-v1 defines g_up
constexpr double kDeg = std::numbers::pi / 180.0;

// Random as-forged part: every level (but the origin level) and diameter off nominal by N(0, σ).
void draw_dimensions(const core::Recipe& recipe, double sigma, std::mt19937_64& rng,
                     SimTruth& truth) {
    std::normal_distribution<double> dev(0.0, sigma);
    for (std::size_t i = 0; i < recipe.levels_mm.size(); ++i) {
        const auto& [name, z] = recipe.levels_mm[i];
        truth.levels_mm[name] = z == 0.0 ? 0.0 : z + dev(rng);
    }
    for (const auto* list : {&recipe.outer, &recipe.inner})
        for (const auto& s : *list) truth.diameters_mm[s.name] = s.diameter_mm + dev(rng);
}

// The die shift's feature name: the recipe's, or "Die shift" (hub-a.md "As forged").
std::string die_shift_name(const core::Recipe& recipe) {
    for (const auto& f : recipe.features)
        if (f.kind == core::FeatureKind::kDieShift) return f.name;
    return "Die shift";
}

// Bad features: a diameter's section, a height's upper level moved by the delta (the die shift
// is moved where it is drawn, draw_forged).
core::Result<void> apply_bad(const core::Recipe& recipe, const SimOptions& opt, SimTruth& truth) {
    for (const auto& [name, delta] : opt.bad_mm) {
        const auto f = std::find_if(recipe.features.begin(), recipe.features.end(),
                                    [&](const core::FeatureSpec& s) { return s.name == name; });
        if (name == die_shift_name(recipe)) {
            if (!opt.forged)
                return core::make_error("simulate --bad '" + name +
                                        "': a die shift needs an as-forged part (--forged)");
        } else if (f == recipe.features.end()) {
            std::string known;
            for (const auto& s : recipe.features) known += (known.empty() ? "" : ", ") + s.name;
            return core::make_error("simulate --bad: no feature '" + name + "' in recipe '" +
                                    recipe.name + "' (" + known + ")");
        } else if (f->kind == core::FeatureKind::kDiameter) {
            truth.diameters_mm.at(f->section) += delta;
        } else {
            const bool to_is_upper =
                recipe.level(f->to_level).value_or(0) >= recipe.level(f->from_level).value_or(0);
            truth.levels_mm.at(to_is_upper ? f->to_level : f->from_level) += delta;
        }
    }
    truth.bad_mm = opt.bad_mm;
    return {};
}

// Every feature's true value of the part as drawn (sharp, vertical, one axis: no die shift).
void true_features(const core::Recipe& recipe, SimTruth& truth) {
    for (const auto& f : recipe.features) {
        double cold = 0.0;
        if (f.kind == core::FeatureKind::kDiameter)
            cold = truth.diameters_mm.at(f.section);
        else if (f.kind == core::FeatureKind::kHeight)
            cold = std::abs(truth.levels_mm.at(f.to_level) - truth.levels_mm.at(f.from_level));
        truth.features.push_back({f.name, cold * truth.growth, cold});
    }
}

// Per wall a draft in [1°, the drawing's], drawn until the flat faces are kept
// (core::flat_faces_kept).
core::Result<void> draw_drafts(const core::Recipe& recipe, std::mt19937_64& rng,
                               core::ForgedShape& shape) {
    auto undrafted = core::build_forged(recipe, shape);
    if (!undrafted) return undrafted.error();
    for (int attempt = 0; attempt < 1000; ++attempt) {
        for (const auto& w : core::forged_walls(recipe))
            shape.draft_deg[w.name] = core::draw_within(recipe.draft_of(w.section), rng);
        auto part = core::build_forged(recipe, shape);
        if (!part) return part.error();
        if (core::flat_faces_kept(*undrafted, *part)) return {};
    }
    return core::make_error("simulate --forged: recipe '" + recipe.name +
                            "': no drafts within the drawing keep its flat faces");
}

// As forged: drafts (draw_drafts), per corner a fillet in [1 mm, the drawing's] (cut down where
// its faces are narrow), the die shift uniform in [0, 0.8 × the drawing's] at a random azimuth;
// from a stream of their own.
core::Result<core::ForgedPart> draw_forged(const core::Recipe& recipe, const SimOptions& opt,
                                           const SimTruth& truth) {
    if (!recipe.forging)
        return core::make_error("simulate --forged: recipe '" + recipe.name + "' (" +
                                recipe.source +
                                ") has no 'forging' drawing (parting plane, draft, fillets, "
                                "die shift)");
    std::mt19937_64 rng(opt.seed ^ 0x666f72676564ull);
    core::ForgedShape shape;
    shape.levels_mm = truth.levels_mm;
    shape.diameters_mm = truth.diameters_mm;
    shape.scale = truth.growth;
    if (auto ok = draw_drafts(recipe, rng, shape); !ok) return ok.error();
    for (const auto& c : core::forged_corners(recipe))
        shape.fillet_mm[c.name] = core::draw_within(recipe.fillet_at(c.level), rng);
    std::uniform_real_distribution<double> u01(0.0, 1.0);
    double shift = 0.8 * recipe.forging->die_shift_mm * u01(rng);
    const double azimuth = 2.0 * std::numbers::pi * u01(rng);
    if (const auto it = opt.bad_mm.find(die_shift_name(recipe)); it != opt.bad_mm.end())
        shift = std::max(0.0, shift + it->second);
    shape.die_shift_mm = shift * Eigen::Vector2d(std::cos(azimuth), std::sin(azimuth));
    return core::build_forged(recipe, shape);
}

// The features at their theoretical sharp corners, and the die shift (hub-a.md "As forged").
void forged_features(const core::Recipe& recipe, SimTruth& truth) {
    const core::ForgedPart& part = *truth.forged;
    for (const auto& f : recipe.features) {
        const double cold = part.feature_cold_mm.at(f.name);
        truth.features.push_back({f.name, cold * truth.growth, cold});
    }
    if (die_shift_name(recipe) == "Die shift" &&
        std::none_of(recipe.features.begin(), recipe.features.end(),
                     [](const core::FeatureSpec& f) { return f.name == "Die shift"; })) {
        const double cold = part.shape.die_shift_mm.norm();
        truth.features.push_back({"Die shift", cold * truth.growth, cold});
    }
}

Eigen::Isometry3d random_placement(const CellConfig& cell, double bottom_radius_mm,
                                   std::mt19937_64& rng) {
    std::uniform_real_distribution<double> u01(0.0, 1.0);
    const double yaw = 2.0 * std::numbers::pi * u01(rng);
    const double tilt = cell.placement.max_tilt_deg * kDeg * u01(rng);
    const double tilt_dir = 2.0 * std::numbers::pi * u01(rng);
    const double m = cell.placement.max_offset_mm;
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.rotate(Eigen::AngleAxisd(tilt, Eigen::Vector3d(std::cos(tilt_dir), std::sin(tilt_dir), 0)));
    T.rotate(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()));
    // Tilted on pins: lift so the lowest rim point just clears the support.
    T.translation() = Eigen::Vector3d(m * (2 * u01(rng) - 1), m * (2 * u01(rng) - 1),
                                      bottom_radius_mm * std::sin(tilt));
    return T;
}

struct RayHit {
    double t;
    Eigen::Vector3d normal;
};

// First hit of the ray o + t·d (d unit, t in (0, t_max)) on the outside of a sphere.
std::optional<RayHit> cast_sphere(const calib::ArtifactSphere& s, const Eigen::Vector3d& o,
                                  const Eigen::Vector3d& d, double t_max) {
    const double r = 0.5 * s.diameter_mm;
    const Eigen::Vector3d oc = o - s.center_mm;
    const double b = d.dot(oc), disc = b * b - (oc.squaredNorm() - r * r);
    if (disc <= 0.0) return std::nullopt;
    const double t = -b - std::sqrt(disc);
    if (t <= 0.0 || t >= t_max) return std::nullopt;
    return RayHit{t, (oc + t * d) / r};
}

// First hit of a world ray on the part, the artifact's spheres or (when visible) the support.
std::optional<RayHit> cast(const Scene::Solid& solid, const Eigen::Isometry3d& T_part_world,
                           const std::vector<calib::ArtifactSphere>& spheres, bool support,
                           double support_half, const Eigen::Vector3d& o, const Eigen::Vector3d& d,
                           double t_max) {
    std::optional<RayHit> best;
    const Eigen::Vector3d op = T_part_world * o, dp = T_part_world.linear() * d;
    const auto part = std::visit([&](const auto& s) { return s.intersect(op, dp, t_max); }, solid);
    if (part) best = RayHit{part->t, T_part_world.linear().transpose() * part->normal};
    for (const auto& s : spheres)
        if (auto h = cast_sphere(s, o, d, best ? best->t : t_max)) best = h;
    if (support && d.z() < 0.0 && o.z() > 0.0) {
        const double t = -o.z() / d.z();
        const Eigen::Vector3d p = o + t * d;
        if (t < (best ? best->t : t_max) && std::abs(p.x()) <= support_half &&
            std::abs(p.y()) <= support_half)
            best = RayHit{t, Eigen::Vector3d::UnitZ()};
    }
    return best;
}

}  // namespace

core::Result<Scene> Scene::create(const core::Recipe& recipe, const CellConfig& cell,
                                  const SimOptions& opt, std::mt19937_64& rng) {
    if (cell.sensor.width < 2) return core::make_error("cell config: sensor.width must be >= 2");
    SimTruth truth;
    truth.temperature_c = opt.temperature_c;
    truth.growth = recipe.material.growth(opt.temperature_c);
    truth.range_noise_mm = cell.sensor.range_noise_mm;
    truth.support_half_size_mm = cell.support_half_size_mm;
    draw_dimensions(recipe, opt.dimension_sigma_mm, rng, truth);
    if (auto ok = apply_bad(recipe, opt, truth); !ok) return ok.error();
    Solid solid = core::AxisymmetricSolid({}, {});
    double bottom_radius = 0.0;
    if (opt.forged) {
        auto part = draw_forged(recipe, opt, truth);
        if (!part) return part.error();
        truth.forged = std::move(*part);
        forged_features(recipe, truth);
        const core::ForgedSolid forged = truth.forged->solid();
        bottom_radius = forged.bottom_radius();
        solid = forged;
    } else {
        true_features(recipe, truth);
        const core::AxisymmetricSolid drawn = truth.solid(recipe);
        for (const auto& s : drawn.boundary())
            if (!s.cylinder && s.value <= 1e-9) bottom_radius = std::max(bottom_radius, s.hi);
        solid = drawn;
    }
    truth.T_world_part =
        opt.T_world_part ? *opt.T_world_part : random_placement(cell, bottom_radius, rng);
    if (opt.occluded_fraction > 0) {
        std::uniform_real_distribution<double> az(0.0, 2.0 * std::numbers::pi);
        truth.occluded_from_rad = az(rng);
        truth.occluded_rad = 2.0 * std::numbers::pi * std::min(1.0, opt.occluded_fraction);
    }
    return Scene(cell, std::move(truth), std::move(solid));
}

Scene Scene::create_artifact(const calib::Artifact& artifact, const CellConfig& cell) {
    SimTruth truth;
    truth.range_noise_mm = cell.sensor.range_noise_mm;
    truth.support_half_size_mm = cell.support_half_size_mm;
    Scene scene(cell, std::move(truth), core::AxisymmetricSolid({}, {}));
    scene.spheres_ = artifact.spheres;
    return scene;
}

Scene::Scene(const CellConfig& cell, SimTruth truth, Solid solid)
    : cell_(cell),
      truth_(std::move(truth)),
      solid_(std::move(solid)),
      T_part_world_(truth_.T_world_part.inverse()) {
    const auto& s = cell_.sensor;
    dir_cam_.resize(static_cast<std::size_t>(s.width));
    for (int i = 0; i < s.width; ++i)
        dir_cam_[i] = Eigen::Vector3d((i - 0.5 * (s.width - 1)) * s.pitch_mm, 0.0, s.standoff_mm)
                          .normalized();
}

// Rays that hit the part inside the occluded sector return nothing.
bool Scene::occluded(const Eigen::Vector3d& p_world) const {
    if (truth_.occluded_rad <= 0) return false;
    const Eigen::Vector3d q = T_part_world_ * p_world;
    const double d = std::visit([&](const auto& s) { return s.distance(q); }, solid_);
    if (std::abs(d) > 1e-3) return false;  // the support, not the part
    double a = std::atan2(q.y(), q.x()) - truth_.occluded_from_rad;
    a -= 2.0 * std::numbers::pi * std::floor(a / (2.0 * std::numbers::pi));
    return a < truth_.occluded_rad;
}

void Scene::cast_profile(const FaceConfig& fc, const Eigen::Vector3d& origin, RandomStream& rng,
                         std::vector<RayReturn>& out, const ProfileEffects& effects) const {
    const auto& s = cell_.sensor;
    constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
    out.assign(static_cast<std::size_t>(s.width), RayReturn{kNaN, kNaN, 0.0f, false});
    const double cos_max_incidence = std::cos(s.max_incidence_deg * kDeg);
    const Eigen::Matrix3d R = fc.T_world_camera.linear();
    const Eigen::Vector3d imager = origin + R * s.imager_mm();
    for (int i = 0; i < s.width; ++i) {
        const Eigen::Vector3d d = R * dir_cam_[i];
        const auto hit = cast(solid_, T_part_world_, spheres_, fc.support_visible,
                              cell_.support_half_size_mm, origin, d, 1e4);
        if (!hit) continue;
        const Eigen::Vector3d p = origin + hit->t * d;
        if (occluded(p)) continue;
        const double range_z = hit->t * dir_cam_[i].z();
        if (range_z < s.min_range_mm || range_z > s.max_range_mm) continue;
        const double cos_incidence = std::abs(hit->normal.dot(d));
        if (cos_incidence < cos_max_incidence) continue;
        // Triangulation needs the imager to see the lit point (unless the cell leaves it out).
        if (s.imager_occlusion) {
            const Eigen::Vector3d to_imager = imager - p;
            const double dist = to_imager.norm();
            if (hit->normal.dot(to_imager) * hit->normal.dot(-d) <= 0.0) continue;
            if (cast(solid_, T_part_world_, spheres_, false, 0.0, p + 1e-6 * to_imager / dist,
                     to_imager / dist, dist))
                continue;
        }
        if (effects.dropouts && rng.uniform() < s.dropout_fraction) continue;
        double along = effects.range_noise ? s.range_noise_mm * rng.normal() : 0.0;
        bool spike = false;
        if (effects.spikes && rng.uniform() < s.spike_fraction) {
            along = s.spike_range_mm * (2.0 * rng.uniform() - 1.0);
            spike = true;
        }
        const double tm = hit->t + along;
        out[i] = RayReturn{static_cast<float>(tm * dir_cam_[i].x()),
                           static_cast<float>(tm * dir_cam_[i].z()),
                           static_cast<float>(cos_incidence), spike};
    }
}

AccelHead::AccelHead(const AccelConfig& a, const Eigen::Matrix3d& R_world_accel, RandomStream& rng)
    : R_world_accel_(R_world_accel),
      noise_mps2_(a.noise_density_ug * 1e-6 * kG * std::sqrt(a.rate_hz / 2.0)),
      clip_mps2_(a.range_g * kG) {
    // Three draws, z first: the order recordings made before this class existed have.
    const double bz = a.bias_mps2 * (2 * rng.uniform() - 1);
    const double by = a.bias_mps2 * (2 * rng.uniform() - 1);
    const double bx = a.bias_mps2 * (2 * rng.uniform() - 1);
    bias_mps2_ = a.fixed_bias_mps2 ? *a.fixed_bias_mps2 : Eigen::Vector3d(bx, by, bz);
}

Eigen::Vector3f AccelHead::sample(const Vibration& vibration, double t_s, RandomStream& rng) const {
    const Eigen::Vector3d acc_world =
        vibration.acceleration_mmps2(t_s) / 1000.0 + Eigen::Vector3d(0, 0, kG);
    Eigen::Vector3d acc = R_world_accel_.transpose() * acc_world + bias_mps2_;
    Eigen::Vector3f out;
    for (int c = 0; c < 3; ++c)
        out[c] = static_cast<float>(
            std::clamp(acc[c] + noise_mps2_ * rng.normal(), -clip_mps2_, clip_mps2_));
    return out;
}

}  // namespace hotgauge::sim
