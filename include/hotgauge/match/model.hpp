#pragma once
// The PPF surface model (docs/matching.md): oriented surface samples of a part, their point pair
// features F = (‖d‖, ∠(n1,d), ∠(n2,d), ∠(n1,n2)) quantised into a dense table (Drost et al.
// 2010, paper §4.2 Fig. 6), and the surface ICP refines against.
//
// Axisymmetric parts (recipes): the rotation about the axis is unobservable, so only the samples
// of one meridian (azimuth 0) are reference points; every scene point on the part then votes for
// that meridian and the spin is fixed by convention (match.hpp), instead of the votes being split
// over all azimuths.
#include <Eigen/Core>
#include <cmath>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "hotgauge/core/part.hpp"
#include "hotgauge/core/result.hpp"

namespace hotgauge::match {

struct ModelConfig {
    double sampling_mm = 5.0;       // model and scene sampling distance
    double distance_step_mm = 0.0;  // PPF distance quantum; 0: sampling_mm
    int angle_bins = 15;            // bins over [0, π] of each feature angle (12°)
    int alpha_bins = 30;            // bins over [−π, π) of the rotation about the normal (12°)
};

inline constexpr std::uint32_t kNoKey = 0xffffffffu;

// One segment of an axisymmetric model's (r, z) boundary, with the material on its left going
// from (r0, z0) to (r1, z1): its outward normal is (z1 − z0, r0 − r1) / length. `wall`: a
// cylinder or a drafted cone, whose radius ICP may free as a nuisance unknown.
struct ProfileSegment {
    double r0 = 0, z0 = 0, r1 = 0, z1 = 0;
    bool wall = false;
    double length() const { return std::hypot(r1 - r0, z1 - z0); }
    // A piece of a fillet's arc: short, neither a wall nor flat nor upright.
    bool fillet_chord() const {
        constexpr double kChordMm = 1.0;
        return !wall && z0 != z1 && r0 != r1 && length() < kChordMm;
    }
};

// Angle of p2 about the x axis once (p1, n1) is moved to the origin with n1 along +x
// (the α of Drost et al.); the model's and the scene's angles differ by the pose's rotation.
float pair_angle(const Eigen::Vector3f& p1, const Eigen::Vector3f& n1, const Eigen::Vector3f& p2);

// The rigid motion that takes p to the origin and n onto +x.
Eigen::Matrix<float, 3, 4> to_ref_frame(const Eigen::Vector3f& p, const Eigen::Vector3f& n);

namespace detail {
class Surface;  // internal.hpp: what ICP and the verification fit against
}

// The model's ICP surface, built at its first match and kept for the next ones (it depends on the
// model alone: 5 % of a part's time in `hotgauge remeasure` went into building it again for each
// part). It refers to its model's data, so a copied or moved model starts without one and builds
// its own. Safe for matches on several threads.
class SurfaceCache {
  public:
    SurfaceCache() = default;
    SurfaceCache(const SurfaceCache&) {}
    SurfaceCache(SurfaceCache&&) noexcept {}
    SurfaceCache& operator=(const SurfaceCache&);
    SurfaceCache& operator=(SurfaceCache&&) noexcept;
    ~SurfaceCache();
    std::shared_ptr<const detail::Surface> get(const struct Model& model) const;

  private:
    mutable std::mutex mutex_;
    mutable std::shared_ptr<const detail::Surface> surface_;
};

// A PPF model. Plain data (model/model_io.hpp saves and loads it); build it with from_recipe or
// from_samples, which keep the table consistent with the samples.
struct Model {
    // Table entry: model reference point and its pair angle.
    struct Entry {
        std::uint32_t ref;  // index into refs
        float alpha;        // pair_angle of the model pair, radians
    };

    std::string name, source;  // part name; what it was built from, for messages
    ModelConfig config;
    bool axisymmetric = false;  // part axis = +z of the part frame
    double diameter_mm = 0;     // largest distance between samples
    double step_mm = 0;         // distance quantum
    // Voting samples (part frame, outward unit normals) and the reference subset.
    std::vector<Eigen::Vector3f> points, normals;
    std::vector<std::uint32_t> refs;
    // The ICP surface: the (r, z) boundary of an axisymmetric model, or dense oriented samples.
    std::vector<ProfileSegment> profile;
    std::vector<Eigen::Vector3f> dense_points, dense_normals;
    // Quantised features → entries, compressed rows: entries[key_begin[k] .. key_begin[k+1]).
    std::vector<std::uint32_t> key_begin;
    std::vector<Entry> entries;
    SurfaceCache surface;  // not data: built from the above when first matched

    int n_distance_bins() const;
    std::uint32_t n_keys() const;
    // Key of the oriented pair (p1, n1) → (p2, n2), or kNoKey (coincident, beyond the table).
    std::uint32_t key(const Eigen::Vector3f& p1, const Eigen::Vector3f& n1,
                      const Eigen::Vector3f& p2, const Eigen::Vector3f& n2) const;
    // Checks the invariants a loaded file must satisfy; the error names what is wrong.
    core::Result<void> validate() const;
};

// From a recipe's nominal cold geometry (axisymmetric, meridian references). A recipe with a
// forging drawing gives the part as drawn at half the drawing's limits (every wall drafted by
// half its largest draft, every corner filleted at half its largest radius: the shape nearest to
// every part the drawing allows), so that a forged part's walls and corners lie on the model;
// without one, the sharp, vertical idealisation.
core::Result<Model> model_from_recipe(const core::Recipe& recipe, const ModelConfig& config = {});

// From oriented surface samples in the part frame (a mesh or a reference scan, sampled densely,
// ~0.5 mm): they are the ICP surface; a `sampling_mm` subset votes, all of it as references.
core::Result<Model> model_from_samples(std::string name, std::string source,
                                       std::vector<Eigen::Vector3f> points,
                                       std::vector<Eigen::Vector3f> normals,
                                       const ModelConfig& config = {});

// (Re)builds key_begin/entries from points, normals, refs, config (after the samples change).
void build_table(Model& model);

}  // namespace hotgauge::match
