#pragma once
// Internals of the match module shared by its translation units (not installed).
#include <Eigen/Geometry>
#include <cstdint>
#include <optional>
#include <vector>

#include "hotgauge/match/match.hpp"

namespace hotgauge::match::detail {

// Oriented scene samples, world frame.
struct Samples {
    std::vector<Eigen::Vector3f> points, normals;
};

// Voting samples of every face: the scan grid thinned to about half the sampling distance,
// normals by PCA over grid neighbours within `normal_radius_mm` (oriented to the sensor), then
// one sample per `sampling_mm` voxel.
Samples voting_samples(const core::Recording& rec, const core::FaceDisplacements& u,
                       double sampling_mm, double normal_radius_mm);

// Points of every face on a grid of about `grid_mm` pitch (no normals).
std::vector<Eigen::Vector3f> grid_points(const core::Recording& rec,
                                         const core::FaceDisplacements& u, double grid_mm);

// A plane n·x = d (n unit).
struct Plane {
    Eigen::Vector3f n;
    float d;
    float distance(const Eigen::Vector3f& p) const { return n.dot(p) - d; }
};

// The largest plane of the samples when it spans more than `min_extent_mm` (so it cannot be a
// face of the part): the support plate, a wall.
std::optional<Plane> background_plane(const Samples& s, double band_mm, double min_extent_mm);

// Closest point of the model surface (part frame, model at `scale`) to q.
struct Closest {
    Eigen::Vector3f point, normal;
    float distance;    // |q − point|
    int segment = -1;  // profile segment of an axisymmetric model (−1: no profile)
    float along = 0;   // where on that segment, mm from its middle
    Eigen::Vector2f radial = Eigen::Vector2f::UnitX();  // (x, y) direction of q from the axis
};

// Point-to-plane ICP of scene points (world) against the model surface.
struct IcpOptions {
    std::vector<double> gates_mm;  // per stage: correspondences farther than this are ignored
    int iterations_per_stage = 8;
    int max_iterations = 30;
    double stop_mm = 1e-4;
    bool estimate_scale = false;
    // Axisymmetric models: each wall gets a free offset and a free tilt of its profile line
    // (nuisance unknowns), so that as-forged diameters and drafts off the model's do not pull
    // the axis where a wall is seen on one side.
    bool free_radii = false;
};
struct IcpResult {
    Eigen::Isometry3d T_world_part;
    double scale = 1;
    double rms_mm = 0;
    std::int64_t used = 0;
    int iterations = 0;
};

class Surface {
  public:
    explicit Surface(const Model& model);
    ~Surface();
    Surface(const Surface&) = delete;
    Surface& operator=(const Surface&) = delete;
    Closest closest(const Eigen::Vector3f& q_part, float scale) const;
    // q (part frame) lies within `margin` of the model's bounding box (cylinder if axisymmetric).
    bool inside_region(const Eigen::Vector3f& q_part, float scale, float margin) const;
    float half_size() const { return half_size_; }
    float max_radius() const { return hi_.x(); }  // axisymmetric models

  private:
    Closest closest_profile(const Eigen::Vector3f& q, float scale) const;
    void build_profile_grid();

    const Model& model_;
    // Profile segments as floats, and a 1 mm (r, z) grid listing for each cell the segments that
    // can hold the closest point of a query in it (the rest are farther than some segment's
    // farthest point of the cell).
    struct Seg {
        float r0, z0, ur, uz, len;  // start, unit direction, length
        float nr, nz;               // outward unit normal (the material is on the left)
        // Squared distance from (r, z) to the segment; t: where its closest point is, in
        // [0, len].
        float distance2(float r, float z, float& t) const;
    };
    std::vector<Seg> segs_;
    float cell_mm_ = 1, r0_ = 0, z0_ = 0;
    int nr_ = 0, nz_ = 0;
    std::vector<std::uint32_t> cell_begin_;
    std::vector<std::uint16_t> cell_segs_;
    Eigen::Vector3f lo_, hi_;  // bounding box, part frame (axisymmetric: r_max, r_max, z range)
    float half_size_ = 0;
    struct KdTree;
    KdTree* tree_ = nullptr;  // dense-sample models only
    float dense_spacing_ = 0;
};

IcpResult icp(const Surface& surface, const Model& model, const std::vector<Eigen::Vector3f>& pts,
              Eigen::Isometry3d T_world_part, double scale, const IcpOptions& options);

// Support of a pose: of the points within the part's bounding region (`margin_mm` around it),
// how many lie within `band_mm` of the surface.
struct Support {
    std::int64_t near = 0, inliers = 0;
    double fraction() const {
        return near > 0 ? static_cast<double>(inliers) / static_cast<double>(near) : 0.0;
    }
};
Support support(const Surface& surface, const std::vector<Eigen::Vector3f>& pts,
                const Eigen::Isometry3d& T_world_part, double scale, double band_mm,
                double margin_mm);

}  // namespace hotgauge::match::detail
