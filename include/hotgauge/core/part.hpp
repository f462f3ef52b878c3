#pragma once
// Part recipes and axisymmetric part geometry (docs/recipes.md). Plain data; the YAML reader
// lives in io (hotgauge/io/recipe.hpp).
#include <Eigen/Core>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace hotgauge::core {

// Mean linear expansion coefficient from 20 °C to T: α(T) = alpha0 + alpha1·(T − 20).
// A cold length L grows to L·(1 + α(T)·(T − 20)) (hub-a.md).
struct ThermalModel {
    double alpha0_per_k = 1.2e-5;
    double alpha1_per_k2 = 3.0e-9;
    double alpha(double t_c) const { return alpha0_per_k + alpha1_per_k2 * (t_c - 20.0); }
    double growth(double t_c) const { return 1.0 + alpha(t_c) * (t_c - 20.0); }
};

// A coaxial section of an axisymmetric part: a cylinder of `diameter_mm` between two named
// z levels (outer contour: material inside the diameter; inner contour: a bore).
struct Section {
    std::string name;
    std::string from_level, to_level;
    double diameter_mm = 0.0;
};

// kDieShift: the distance, perpendicular to the axis, between the axes of the part's upper half
// (above the parting plane) and its lower half (hub-a.md "As forged"); nominal 0.
enum class FeatureKind { kDiameter, kHeight, kDieShift };
enum class HeightMethod { kPlanes, kEdges };  // fitted parallel planes, or edges along the axis

struct FeatureSpec {
    std::string name;  // as reported: "Diameter 3"
    FeatureKind kind = FeatureKind::kDiameter;
    std::vector<std::string> faces;  // faces whose data measure it
    // diameter: the section and the level at which its edge is taken
    std::string section;
    std::string edge_at;
    // height: distance between two levels along the axis
    std::string from_level, to_level;
    HeightMethod height_method = HeightMethod::kPlanes;
    double nominal_mm = 0.0;
    double tol_lower_mm = 0.0;  // allowed deviation below nominal (negative or zero)
    double tol_upper_mm = 0.0;  // allowed deviation above nominal
    int slot = 0;               // result slot (PLC register block index), 1-based
    // The part's verdict waits for it (recipe key `required`, default true). A feature that is
    // not required still reads NOK and makes the part NOK; not measured, it leaves the part's
    // verdict to the others (docs/recipes.md "Features the verdict does not wait for").
    bool required = true;
};

// How the part is found in the scans (docs/matching.md); recipe key `matching`.
struct MatchingSpec {
    double sampling_mm = 5.0;  // model and scene sampling distance of the PPF voting
    double min_score = 0.8;    // fraction of scan points near the part that lie on the model
    double score_band_mm = 0;  // "on the model" within this (0: matching's own 0.3 mm)
};

// What the forging drawing allows (docs/recipes.md "The forging drawing"); recipe key `forging`.
// These are limits, not the part: the measurement finds each part's own draft and radii within
// them (a sharp, vertical part is one legal case). Features stay defined at the theoretical
// sharp corners. A recipe without the key describes sharp corners and vertical walls on one axis.
struct ForgingSpec {
    double parting_z_mm = 0.0;  // the parting plane, part frame, cold
    double draft_deg = 0.0;     // largest draft of a wall ("draft ≤ 3°")
    double fillet_mm = 0.0;     // largest fillet radius of a corner ("R ≤ 2.5")
    double die_shift_mm = 0.0;  // largest die shift the drawing allows
    std::map<std::string, double> section_draft_deg;  // per section, where the drawing says
    std::map<std::string, double> level_fillet_mm;    // per level (both its corners)

    double draft_of(const std::string& section) const {
        const auto it = section_draft_deg.find(section);
        return it == section_draft_deg.end() ? draft_deg : it->second;
    }
    double fillet_at(const std::string& level) const {
        const auto it = level_fillet_mm.find(level);
        return it == level_fillet_mm.end() ? fillet_mm : it->second;
    }
};

struct Recipe {
    std::string name;
    std::string source;     // file it came from, for messages
    std::string mesh_file;  // optional surface model (PLY/STL), absolute path; "" if none
    std::vector<std::pair<std::string, double>> levels_mm;  // named z levels, part frame, cold
    std::vector<Section> outer, inner;
    ThermalModel material;
    MatchingSpec matching;
    std::optional<ForgingSpec> forging;  // absent: sharp corners, vertical walls, one axis
    std::vector<FeatureSpec> features;

    // Upper bound of the fillet radius at a level's corners (0 without a forging drawing).
    double fillet_at(const std::string& level_name) const {
        return forging ? forging->fillet_at(level_name) : 0.0;
    }
    double draft_of(const std::string& section_name) const {
        return forging ? forging->draft_of(section_name) : 0.0;
    }

    std::optional<double> level(const std::string& level_name) const;
    const Section* section(const std::string& section_name) const;
    bool is_inner(const Section& s) const {
        return &s >= inner.data() && &s < inner.data() + inner.size();
    }
};

// The solid of revolution of a recipe's sections (part frame: axis +z, mm), possibly scaled
// (thermal growth) and with actual (non-nominal) dimensions. Surfaces are cylinders and annular
// planes; the boundary of the (r, z) half cross-section is a list of axis-parallel segments.
class AxisymmetricSolid {
  public:
    struct Slab {
        double z0, z1, radius;
    };
    struct Segment {
        bool cylinder;  // true: r = value, z in [lo, hi]; false: plane z = value, r in [lo, hi]
        double value, lo, hi;
    };
    struct Hit {
        double t;                // ray parameter, mm
        Eigen::Vector3d normal;  // unit surface normal, pointing out of the material
    };

    AxisymmetricSolid(std::vector<Slab> outer, std::vector<Slab> inner);
    // From a recipe, with optional actual dimensions (level name -> z, section name -> diameter)
    // and a uniform scale about the part origin (thermal growth).
    static AxisymmetricSolid from_recipe(const Recipe& recipe,
                                         const std::map<std::string, double>& level_mm = {},
                                         const std::map<std::string, double>& diameter_mm = {},
                                         double scale = 1.0);

    bool inside(double r, double z) const;
    const std::vector<Segment>& boundary() const { return boundary_; }
    double height() const { return z_max_ - z_min_; }
    double max_radius() const { return r_max_; }
    // Unsigned distance from a part-frame point to the surface.
    double distance(const Eigen::Vector3d& p) const;
    // First intersection of the ray origin + t·dir (dir unit, part frame) with t in (0, t_max).
    std::optional<Hit> intersect(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir,
                                 double t_max) const;

  private:
    std::vector<Slab> outer_, inner_;
    std::vector<Segment> boundary_;
    double z_min_ = 0, z_max_ = 0, r_max_ = 0;
};

}  // namespace hotgauge::core
