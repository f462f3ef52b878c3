#pragma once
// One face of a recording in the part frame (docs/measurement.md, "Preparation"): samples on
// demand, the samples near the part bucketed by z, and a ray model per column. Internal to
// the measure module.
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "hotgauge/core/recording.hpp"

namespace hotgauge::measure::detail {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// One face in the part frame. Any sample (profile k, column i) is transformed on demand; the
// samples near the part (inside its bounding cylinder, with a margin) are kept transformed and
// bucketed by z, so a query for a level or a z range visits only the samples near it. Each
// column has a ray model: in the camera frame its points lie on x = a_i + b_i·z (estimated
// from the data), so a sample without a return still has a known ray.
struct FaceFrame {
    const core::FaceScan* scan = nullptr;
    std::int64_t n = 0, w = 0;
    Eigen::Matrix3d M;                    // camera -> part rotation
    std::vector<Eigen::Vector3d> origin;  // per profile: camera origin in the part frame
    std::vector<double> col_a, col_b;
    Eigen::Vector3d view;  // camera +z (away from the sensor), part frame
    // The compensation's own error on this face (drift.hpp), or null: not known.
    const core::DisplacementNoise* noise = nullptr;

    struct Near {
        std::int64_t q;     // k·w + i
        Eigen::Vector3f p;  // part frame
        float r;            // distance from the part axis
    };
    static constexpr double kBucketMm = 0.5;
    double z0 = 0;
    std::vector<Near> near;            // ordered by z bucket
    std::vector<std::int64_t> bucket;  // start of each bucket in `near`, plus an end sentinel

    // Calls f(const Near&) for the near-part samples with z in about [lo, hi] (whole buckets:
    // callers check exact bounds).
    template <class F>
    void for_z(double lo, double hi, F&& f) const {
        const auto nb = static_cast<std::int64_t>(bucket.size()) - 1;
        if (nb < 1 || hi < lo) return;
        const auto b0 = std::clamp<std::int64_t>(
            static_cast<std::int64_t>(std::floor((lo - z0) / kBucketMm)), 0, nb - 1);
        const auto b1 = std::clamp<std::int64_t>(
            static_cast<std::int64_t>(std::floor((hi - z0) / kBucketMm)), 0, nb - 1);
        for (std::int64_t j = bucket[b0]; j < bucket[b1 + 1]; ++j) f(near[j]);
    }

    // Profiles the compensation could not follow (empty: none): no sample of theirs is valid,
    // and an edge test must not take them for "no return" (left_out).
    std::vector<std::uint8_t> untrusted;
    bool left_out(std::int64_t k) const {
        return !untrusted.empty() && k >= 0 && k < n && untrusted[static_cast<std::size_t>(k)];
    }
    bool valid(std::int64_t k, std::int64_t i) const {
        return k >= 0 && k < n && i >= 0 && i < w && !left_out(k) && std::isfinite(scan->x(k, i)) &&
               std::isfinite(scan->z(k, i));
    }
    Eigen::Vector3d point(std::int64_t k, std::int64_t i) const {
        return M * Eigen::Vector3d(scan->x(k, i), 0.0, scan->z(k, i)) + origin[k];
    }
    double radius(std::int64_t k, std::int64_t i) const {
        const Eigen::Vector3d p = point(k, i);
        return std::sqrt(p.x() * p.x() + p.y() * p.y());
    }
    double range(std::int64_t k, std::int64_t i) const { return scan->z(k, i); }
    // The ray of sample (k, i) as o + s·d, s = camera z.
    Eigen::Vector3d ray_origin(std::int64_t k, std::int64_t i) const {
        return origin[k] + M * Eigen::Vector3d(col_a[i], 0.0, 0.0);
    }
    Eigen::Vector3d ray_dir(std::int64_t i) const {
        return M * Eigen::Vector3d(col_b[i], 0.0, 1.0);
    }
};

// `r_max`, `z_lo`, `z_hi`: the part's bounding cylinder (hot, with margin), part frame. `u`:
// the sensor's world displacement per profile (compensation), or null. `untrusted`: runs of
// profiles left out of the frame, or null.
FaceFrame make_frame(const core::FaceScan& f, const Eigen::Isometry3d& T_part_world,
                     const std::vector<Eigen::Vector3d>* u,
                     const std::vector<core::UntrustedProfiles>* untrusted, double r_max,
                     double z_lo, double z_hi);

// Expected hot geometry: nominal × growth, and how much to widen windows for what is unknown.
struct Expect {
    double g = 1.0;      // growth used for expectations
    double slack = 0.0;  // relative uncertainty of g
    double z(double nominal) const { return nominal * g; }
    double tol(double base, double size) const { return base + std::abs(size) * g * slack; }
};

}  // namespace hotgauge::measure::detail
