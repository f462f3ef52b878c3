#pragma once
// A calibration artifact of known geometry (docs/calibration.md "Artifact file"): spheres, and
// optionally planes, in the artifact frame, which is the world frame of the cell during the scan.
// Other tools write the file too; it is a contract, read strictly.
#include <Eigen/Core>
#include <filesystem>
#include <string>
#include <vector>

#include "hotgauge/core/result.hpp"
#include "hotgauge/io/bytes.hpp"

namespace hotgauge::calib {

struct ArtifactSphere {
    std::string name;
    Eigen::Vector3d center_mm = Eigen::Vector3d::Zero();
    double diameter_mm = 0.0;
};

struct ArtifactPlane {
    std::string name;
    Eigen::Vector3d point_mm = Eigen::Vector3d::Zero();
    Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  // unit
};

struct Artifact {
    std::string name;  // a recording of it has part.yaml `recipe` = name
    std::vector<ArtifactSphere> spheres;
    std::vector<ArtifactPlane> planes;
};

// The artifact's surfaces, numbered: 0..S−1 the spheres, S.. the planes.
std::size_t surface_count(const Artifact& artifact);
const std::string& surface_name(const Artifact& artifact, std::size_t surface);
// Signed distance of world point p from surface j (outside positive) and its unit gradient.
double surface_distance(const Artifact& artifact, std::size_t j, const Eigen::Vector3d& p,
                        Eigen::Vector3d& normal);

// Reads ARTIFACT.yaml: at least 3 spheres, names unique, diameters positive, no two spheres
// overlapping, normals non-zero (normalised on reading). Errors name file:line and the key.
core::Result<Artifact> read_artifact(const std::filesystem::path& file);
// The same on the file's text, `file` naming it in errors.
core::Result<Artifact> parse_artifact(std::string_view text, const std::filesystem::path& file);

}  // namespace hotgauge::calib
