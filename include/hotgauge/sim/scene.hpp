#pragma once
// The simulated cell's physics, one profile or one accelerometer sample at a time: the as-forged
// part placed on the support, what one laser fan returns from a given sensor position, and what
// the accelerometer in the head reads. simulate() scans whole faces with it; the virtual cell
// (`hotgauge simulate --serve`) renders camera frames and accelerometer datagrams with it at the
// times they are sent.
#include <Eigen/Geometry>
#include <cstdint>
#include <random>
#include <variant>
#include <vector>

#include "hotgauge/core/forged.hpp"
#include "hotgauge/core/part.hpp"
#include "hotgauge/core/result.hpp"
#include "hotgauge/sim/simulator.hpp"
#include "hotgauge/sim/vibration.hpp"

namespace hotgauge::sim {

// What one ray of the fan returns, camera frame. x_mm, z_mm are NaN when there is no return.
struct RayReturn {
    float x_mm, z_mm;
    float cos_incidence;  // |n·d| at the lit point (brightness of a diffuse surface)
    bool spike;           // a gross outlier along the ray (a reflection)
};

// A scan's random stream: the engine and the normal distribution, whose state (a cached second
// deviate) is part of the stream.
struct RandomStream {
    explicit RandomStream(std::uint64_t seed) : engine(seed) {}
    double normal() { return gauss(engine); }
    double uniform() { return std::uniform_real_distribution<double>(0.0, 1.0)(engine); }
    std::mt19937_64 engine;
    std::normal_distribution<double> gauss{0.0, 1.0};
};

// Which of the sensor's imperfections a profile gets.
struct ProfileEffects {
    bool range_noise = true;  // σ along the ray
    bool dropouts = true;
    bool spikes = true;
};

// The part as forged and placed. Immutable after creation; cast_profile is const and thread-safe
// given one rng per thread.
class Scene {
  public:
    // Draws the part's dimensions and placement from `rng` (SimOptions: seed, temperature,
    // pose, σ, occlusion) and fills the truth's part fields.
    static core::Result<Scene> create(const core::Recipe& recipe, const CellConfig& cell,
                                      const SimOptions& options, std::mt19937_64& rng);
    // The artifact's spheres (world frame) in place of a part.
    static Scene create_artifact(const calib::Artifact& artifact, const CellConfig& cell);

    const SimTruth& truth() const { return truth_; }
    SimTruth& truth() { return truth_; }

    // One fan from the sensor origin `origin_world` (nominal pose + travel + vibration;
    // orientation of `face`): `out` gets cell.sensor.width returns.
    void cast_profile(const FaceConfig& face, const Eigen::Vector3d& origin_world,
                      RandomStream& rng, std::vector<RayReturn>& out,
                      const ProfileEffects& effects = {}) const;

    // The part as drawn (sharp, vertical, one axis) or as forged.
    using Solid = std::variant<core::AxisymmetricSolid, core::ForgedSolid>;

  private:
    Scene(const CellConfig& cell, SimTruth truth, Solid solid);
    bool occluded(const Eigen::Vector3d& p_world) const;

    CellConfig cell_;
    SimTruth truth_;
    Solid solid_;
    std::vector<calib::ArtifactSphere> spheres_;  // world frame
    Eigen::Isometry3d T_part_world_;
    std::vector<Eigen::Vector3d> dir_cam_;  // ray directions, camera frame
};

// The accelerometer in the sensor head while it scans one face:
// a = R_world_accelᵀ·(ü/1000 + g_up) + bias + white noise, clipped to the range.
class AccelHead {
  public:
    // Draws the per-axis bias from `rng`.
    AccelHead(const AccelConfig& config, const Eigen::Matrix3d& R_world_accel, RandomStream& rng);
    // One sample at t_s on the vibration's time axis, m/s², accelerometer axes.
    Eigen::Vector3f sample(const Vibration& vibration, double t_s, RandomStream& rng) const;
    // The head was moved to another face: same sensor, other orientation.
    void set_R_world_accel(const Eigen::Matrix3d& R) { R_world_accel_ = R; }

  private:
    Eigen::Matrix3d R_world_accel_;
    Eigen::Vector3d bias_mps2_;
    double noise_mps2_, clip_mps2_;
};

}  // namespace hotgauge::sim
