#pragma once
// The vibration compensation's own error in a feature (docs/measurement.md "Uncertainty",
// docs/compensation.md "Its own error"): the accelerometer's noise, integrated twice, leaves each
// face's displacement wrong by a slowly varying e(t) (core::DisplacementNoise), a few
// micrometres that stay for a few hundred milliseconds. A fit does not see it: it moves whole
// stretches of profiles together.
#include <Eigen/Core>
#include <string>
#include <utility>
#include <vector>

#include "frame.hpp"

namespace hotgauge::measure::detail {

// A feature that is, to first order, a weighted sum Σ w_i·p_i of its samples' positions (part
// frame) is off by Σ w_i·e(t_i): e of the sample's face at its profile's time, the faces' errors
// independent of each other. add() takes the weights profile by profile; u() is the standard
// deviation of the sum, 0 when no face has a known noise model.
// The bridged holes of a face's accelerometer record add their own error
// (core::DisplacementNoise::hole_sigma): per hole and axis one unknown, so its share is
// Σ w_i·σ(t_i) over the profiles it reaches, in quadrature over holes, axes and faces: u_holes().
class DriftSum {
  public:
    void add(const FaceFrame& fr, std::int64_t profile, const Eigen::Vector3d& w_part);
    double u() const;
    double u_holes() const;

  private:
    struct Face {
        const FaceFrame* fr;
        Eigen::Matrix3d R_world_part;
        std::vector<Eigen::Vector3d> bins;   // world weights per lag_s of the face's time
        std::vector<Eigen::Vector3d> holes;  // per hole: Σ world weight × σ
    };
    std::vector<Face> faces_;
};

// The holes' share as its own term of a feature's u ("accelerometer holes"), when there is one.
constexpr const char* kHolesTerm = "accelerometer holes";
void add_holes_term(std::vector<std::pair<std::string, double>>& budget, const DriftSum& d);

// A plane's inliers as fit_level_plane keeps them (`keys`: face index in `frames` << 32 |
// profile): their mean moves by the mean of their e, `w` along it.
void add_plane(DriftSum& d, const std::vector<const FaceFrame*>& frames,
               const std::vector<std::int64_t>& keys, const Eigen::Vector3d& w);

// A diameter's samples of profile k of `fr`: `radial_sum`, the sum of their unit vectors away from
// the circle's centre in the circle's plane (basis e1, e2, part frame), of `n` samples in all.
// The radius moves by the mean of their errors along those vectors, the diameter by twice that.
void add_radial(DriftSum& d, const FaceFrame& fr, std::int64_t k, const Eigen::Vector2d& radial_sum,
                const Eigen::Vector3d& e1, const Eigen::Vector3d& e2, double n);

}  // namespace hotgauge::measure::detail
