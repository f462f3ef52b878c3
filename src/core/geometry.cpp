#include "hotgauge/core/geometry.hpp"

#include <cmath>

namespace hotgauge::core {

bool is_rotation(const Eigen::Matrix3d& R, double tol) {
    if (!R.allFinite()) return false;
    const double orth = (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
    return orth <= tol && std::abs(R.determinant() - 1.0) <= tol;
}

FaceCloud world_cloud(const FaceScan& face, const std::vector<Eigen::Vector3d>* displacement_mm) {
    FaceCloud cloud;
    const std::int64_t n = face.n_profiles();
    cloud.points_mm.reserve(static_cast<std::size_t>(n * face.width / 2));
    for (std::int64_t k = 0; k < n; ++k) {
        Eigen::Vector3d shift = face.profile_positions_mm[k] * face.scan_direction;
        if (displacement_mm) shift += (*displacement_mm)[k];
        for (std::int64_t i = 0; i < face.width; ++i) {
            const float x = face.x(k, i), z = face.z(k, i);
            if (std::isnan(x) || std::isnan(z)) continue;
            cloud.points_mm.push_back(face.T_world_camera * Eigen::Vector3d(x, 0.0, z) + shift);
            cloud.profile.push_back(static_cast<std::int32_t>(k));
            cloud.column.push_back(static_cast<std::int32_t>(i));
        }
    }
    return cloud;
}

}  // namespace hotgauge::core
