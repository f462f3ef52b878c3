#pragma once
// A forging as it leaves the press (shared/docs/hub-a.md "As forged"; docs/simulator.md
// "As-forged parts"): every wall a cone drafted away from the parting plane, every corner
// filleted, the upper die's half beside the lower one (die shift). The part is two solids of
// revolution that meet at the parting plane: the lower half (z <= parting plane) about the part
// axis, the upper half (z >= parting plane) about the axis shifted by the die shift.
//
// Features stay defined at the theoretical sharp corners: each wall's cone is anchored so that it
// meets its diameter feature's level plane at exactly half that diameter; a wall piece without a
// feature of its own (the other half of a wall across the parting plane) continues its anchored
// half at the parting plane.
#include <Eigen/Core>
#include <map>
#include <optional>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "hotgauge/core/part.hpp"
#include "hotgauge/core/result.hpp"

namespace hotgauge::core {

// One part's drawn forging: cold mm, part frame. Names come from forged_walls / forged_corners.
struct ForgedShape {
    std::map<std::string, double> levels_mm;     // actual levels (missing: nominal)
    std::map<std::string, double> diameters_mm;  // per section, at its anchor (missing: nominal)
    std::map<std::string, double> draft_deg;     // per wall (missing: 0, a cylinder)
    std::map<std::string, double> fillet_mm;     // per corner, as drawn (missing: 0, sharp)
    Eigen::Vector2d die_shift_mm = Eigen::Vector2d::Zero();  // upper half's axis, part x, y
    double scale = 1.0;  // uniform growth about the part origin (thermal), for the solid only
};

// A wall: a section, or one half of a section across the parting plane ("<section> lower",
// "<section> upper"), with the section it belongs to (whose draft limit applies).
struct ForgedWall {
    std::string name, section;
};
// A corner: a vertex of the sharp profile on a level ("<level> inner" / "<level> outer" for the
// smaller / larger radius of a level's two corners, "<level> 1".. when it has other than two),
// with that level (whose fillet limit applies).
struct ForgedCorner {
    std::string name, level;
};
std::vector<ForgedWall> forged_walls(const Recipe& recipe);
std::vector<ForgedCorner> forged_corners(const Recipe& recipe);

// The solid: two closed (r, z) profiles, each about its own axis, meeting at the parting plane.
// A profile runs from one parting-plane vertex to the other with the material on its left (the
// closing segment along the parting plane is implied); fillets are chords. Where the halves'
// parting-plane annuli do not overlap (die shift), the uncovered part of each is a surface.
// Immutable; intersect/inside/distance are const and thread-safe.
class ForgedSolid {
  public:
    using Profile = std::vector<Eigen::Vector2d>;  // (r, z) mm
    ForgedSolid(Profile lower, Profile upper, double parting_z_mm, Eigen::Vector2d upper_axis_mm);

    bool inside(const Eigen::Vector3d& p) const;
    // Unsigned distance from a part-frame point to the surface.
    double distance(const Eigen::Vector3d& p) const;
    // First intersection of origin + t·dir (dir unit, part frame) with t in (0, t_max), with the
    // outward unit normal.
    std::optional<AxisymmetricSolid::Hit> intersect(const Eigen::Vector3d& origin,
                                                    const Eigen::Vector3d& dir, double t_max) const;
    double max_radius() const;     // about the part axis
    double bottom_radius() const;  // outer end of the lowest flat face (the support contact)
    double parting_z_mm() const { return parting_z_; }

  private:
    struct Segment {
        double r0, z0, ur, uz, len;  // start, unit direction, length
        double a, b, c;              // line a·r + b·z + c = 0, (a, b) the outward unit normal
    };
    struct Group {  // consecutive segments and their (r, z) bounding box
        double r_lo, r_hi, z_lo, z_hi;
        std::size_t begin, end;
    };
    struct Half {
        Profile profile;
        Eigen::Vector2d axis;  // part x, y of this half's axis
        std::vector<Segment> segments;
        std::vector<Group> groups;
        double r_max = 0, r_in = 0, r_out = 0;  // r_in, r_out: its parting-plane annulus
    };
    static Half make_half(Profile profile, const Eigen::Vector2d& axis);
    std::optional<AxisymmetricSolid::Hit> intersect_half(const Half& h, const Eigen::Vector3d& o,
                                                         const Eigen::Vector3d& d,
                                                         double& t_best) const;
    bool on_parting_face(const Eigen::Vector3d& p, bool* lower_face) const;

    Half lower_, upper_;
    double parting_z_;
};

// One built part: the profiles (cold), the fillets as fitted, and every feature at its sharp
// corner (cold; the hot value is × shape.scale).
struct ForgedPart {
    ForgedShape shape;
    double parting_z_mm = 0;                        // actual, cold
    ForgedSolid::Profile lower_sharp, upper_sharp;  // without fillets
    ForgedSolid::Profile lower, upper;              // with fillets (chords)
    std::map<std::string, double> fillet_mm;        // per corner as built: fits its faces
    std::map<std::string, double> draft_deg;        // per wall as built
    std::map<std::string, double> feature_cold_mm;  // recipe feature name -> sharp-corner value
    // Each flat face of the sharp profile in profile order: its level and its signed width
    // (r at its end − r at its start; the sign is the way it faces, so a face the drafts turned
    // over has the other sign than on the part without draft).
    std::vector<std::pair<std::string, double>> level_faces_mm;

    // The hot part as scanned (× shape.scale), part frame.
    ForgedSolid solid() const;
};

// Builds a part from the recipe (sections, levels, the parting plane of its `forging`) and one
// part's drawn shape. The parting plane follows the part: it keeps its place between the two
// levels around it (hub-a: the flange's mid-thickness). A fillet is cut down where its faces are
// narrow: its radius and its tangent length are at most 0.4 × each of its two faces. Errors when
// the sections do not stack (outer, inner: each section starts where the one below ends) or the
// parting plane does not cross an outer and an inner wall (or the axis).
Result<ForgedPart> build_forged(const Recipe& recipe, const ForgedShape& shape);

// The rules by which a forging is drawn within its drawing (the simulator's and the Embree
// oracle's parts): a draft or fillet uniform in [1, max] ([max, max] below 1, 0 for none), and
// the die designer's check that every flat face keeps at least min(its width without draft,
// max(0.3 mm, a fifth of it)) — drafts that fail it are drawn again.
double draw_within(double max, std::mt19937_64& rng);
bool flat_faces_kept(const ForgedPart& undrafted, const ForgedPart& part);

}  // namespace hotgauge::core
