#pragma once
// Normals of an unorganised point set: a reference scan saved without them (docs/model-file.md).
// The scene's normals come from the scan grid instead (internal.hpp, voting_samples).
#include <Eigen/Core>
#include <vector>

#include "hotgauge/core/result.hpp"

namespace hotgauge::match {

struct OrientedPoints {
    std::vector<Eigen::Vector3f> points;   // mm
    std::vector<Eigen::Vector3f> normals;  // unit, one per point
};

// Each point's normal is the PCA normal (smallest eigenvector of the covariance) of its 12
// nearest neighbours and itself (exact FLANN k-d tree search), oriented towards +z: the sensor
// looks down the scan's −z, and on walls parallel to z that side is arbitrary. Points whose
// neighbourhood is a line or a single point get no normal and are left out, so the result may
// hold fewer points than the input, in the input's order. An error only if FLANN throws.
core::Result<OrientedPoints> estimate_normals(const std::vector<Eigen::Vector3f>& points);

}  // namespace hotgauge::match
