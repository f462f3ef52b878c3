#pragma once
// From a registered recording to the dimensions a quality engineer signs off: the recipe's
// features measured in the part frame (docs/measurement.md).
#include <Eigen/Geometry>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "hotgauge/core/part.hpp"
#include "hotgauge/core/recording.hpp"

namespace hotgauge::measure {

struct MeasureConfig {
    double plane_band_mm = 1.0;       // preselection of plane points around the expected level
    double wall_band_mm = 1.0;        // preselection of wall points around the expected radius
    double unknown_growth = 0.025;    // relative growth to allow for when T is unknown
    double support_margin_mm = 0.6;   // keep plane/wall samples this far from their ends
    double edge_window_mm = 2.5;      // edge search around the expected edge
    double on_surface_k_sigma = 3.0;  // a sample is on a fitted surface within k·rms ...
    double on_surface_min_mm = 0.15;  // ... but never tighter than this
    double normal_edge_deg = 30.0;    // coarse edge: local normal this far from the plane's
    double fine_window_mm = 1.5;      // fine edge search around the coarse edge circle ...
    double refine_window_mm = 0.5;    // ... and again around the first fine circle
    double max_pair_gap_mm = 2.0;     // neighbour samples farther apart do not bracket an edge
    int min_plane_points = 50;
    // Faces are prepared and features measured on this many threads (0: one per core). Each
    // feature's computation is the same on any thread, so results do not depend on it.
    int threads = 0;
    int min_edge_points = 20;
    double free_centre_min_arc_deg = 300.0;         // below: the circle is centred on the part axis
    double max_partial_arc_disagreement_mm = 0.05;  // ... unless a free fit disagrees more
    double min_arc_deg = 30.0;        // a circle seen on less arc than this is not measured
    int sectors = 8;                  // multiple sampling (paper §4.3): sector fits
    double max_axis_offset_mm = 1.0;  // an edge circle centred this far off the part axis, or
    double max_plane_tilt_deg = 3.0;  // a plane this tilted from it: wrong pose or wrong part
    // Standard uncertainty of the part axis's direction from the pose (match: worst 0.016° over
    // 200 random placements, docs/matching.md): enters heights that rely on the axis's lean.
    double pose_axis_u_deg = 0.01;
    // Standard uncertainty of the pyrometer's reading (a two-colour pyrometer on scaled steel:
    // a few kelvin): enters the cold value through the growth's slope dg/dT.
    double temperature_u_c = 5.0;
    // A feature whose u from the accelerometer's bridged holes (the "accelerometer holes" term,
    // docs/compensation.md "Holes in u") exceeds this is degraded: its 2u alone would take two
    // thirds of the ±0.015 mm the gauge is built for. 0.0075 mm let Diameter 6 read 0.043 mm
    // off unflagged (holes term 0.0065 mm) at 10 % loss on independent-paper-7.
    double max_holes_u_mm = 0.005;
    // ... and one measured around them whose u exceeds this: ±0.02 mm is the bound a value is
    // held to under datagram loss (issue 38), and its u alone would fill it.
    double max_u_beside_holes_mm = 0.02;
};

// kDegraded: measured, but only with profiles the compensation could not follow (an
// accelerometer gap, bad samples, the record's end): the value is reported and must not sort the
// part, whatever its deviation (docs/compensation.md "Gaps and degraded features").
enum class Verdict { kOk, kNok, kNotMeasured, kDegraded };
const char* to_string(Verdict v);

// How one end of a height, or the edge of a diameter, was found (docs/measurement.md):
//   "plane"            the level's flat face, fitted (paper §4.3.1)
//   "convex corner"    both faces of the edge seen: the fitted face meets the fitted wall
//   "concave corner"   the wall standing on the support plate: the fitted plate meets the wall
//   "silhouette edge"  one face seen: brackets of neighbouring rays across the edge
struct EdgeEstimate {
    std::string level;      // recipe level
    std::string estimator;  // one of the four above
    std::vector<std::string> faces;
    double value_mm = 0;  // heights: z of the end (hot part frame); diameters: edge radius
    double u_mm = 0;      // standard uncertainty of value_mm from its fit
    std::int64_t n_points = 0;
};

struct FeatureResult {
    std::string name;
    core::FeatureKind kind = core::FeatureKind::kDiameter;
    int slot = 0;
    std::vector<std::string> faces;
    Verdict verdict = Verdict::kNotMeasured;
    bool required = true;  // the part's verdict waits for it (core::FeatureSpec::required)
    std::string reason;    // why not measured / NOK / degraded; empty when OK
    // What the data lacked, for the PLC's reason bits (docs/plc-modbus.md "Reason bits"): a face
    // it needs is not in the recording; its edge seen on less than free_centre_min_arc_deg.
    bool face_missing = false;
    bool low_coverage = false;
    // Untrusted profiles of its faces (core::describe of each run): left out of its fits, or,
    // when it could not be measured without them, used and the feature degraded.
    std::vector<std::string> left_out;
    bool degraded = false;
    // Why a degraded value is not vouched for, before its left_out runs in the reason; empty:
    // "measured with untrusted profiles".
    std::string degraded_because;
    std::optional<double> hot_mm;     // as measured at the part temperature
    std::optional<double> cold_mm;    // hot / (1 + α(T)·(T − 20)); needs the temperature
    std::optional<double> u_cold_mm;  // cold_mm's standard uncertainty: u_mm and the pyrometer's
    double nominal_mm = 0, tol_lower_mm = 0, tol_upper_mm = 0;
    std::optional<double> deviation_mm;  // cold − nominal
    double fit_rms_mm = 0;               // RMS residual of the fit(s) behind the value
    std::int64_t n_points = 0;           // points behind the value (edge points, plane points)
    double u_mm = 0;  // standard uncertainty of hot_mm: the budget's terms in quadrature
    std::vector<std::pair<std::string, double>> u_budget;  // term name, standard uncertainty
    std::optional<double> sector_spread_mm;  // std of the sector values (multiple sampling)
    // Heights from silhouette edges: the sector values' spread beyond each sector's own
    // uncertainty (random effects, τ); the "sectors" term is then τ/√n_sectors.
    std::optional<double> sector_between_mm;
    int n_sectors = 0;
    double arc_deg = 0;  // diameters: angular coverage of the edge points
    std::string method;  // "edge circle", "planes", "plane and edge", "edges" (empty: none)
    std::vector<EdgeEstimate> ends;  // heights: from, to; diameters: the edge
    // Diameters: the circle's own centre (hot, part frame), for the die shift.
    std::optional<Eigen::Vector3d> centre_mm;
    // A forging's diameter whose corner looked to the faces that see its wall for the draft
    // (PartMeasurer: measured again when more of them come in).
    bool wall_faces_used = false;
};

struct PartMeasurement {
    std::vector<FeatureResult> features;  // in recipe order
    Verdict verdict = Verdict::kNotMeasured;
    std::optional<double> temperature_c;
    std::optional<double> growth;  // 1 + α(T)·(T − 20) when T is known
};

// Per-face world displacement of the sensor per profile (compensation); absent = none.
// Per face, the runs of profiles the compensation could not follow; absent = all trusted.
using FaceUntrusted = core::FaceUntrusted;

// Measures every feature of `recipe` on `rec`, with the part at `T_world_part`. Untrusted
// profiles are left out of every feature's fits; a feature that cannot be measured without them
// is measured with them and degraded. Never throws; what cannot be measured is reported as such
// with a reason.
PartMeasurement measure_part(const core::Recipe& recipe, const core::Recording& rec,
                             const Eigen::Isometry3d& T_world_part,
                             const core::FaceDisplacements& displacement_mm = {},
                             const MeasureConfig& config = {}, const FaceUntrusted& untrusted = {},
                             const core::FaceDisplacementNoise& noise = {});

// Every measured feature of `m` degraded because of `why` (a face left out, so the pose was
// found without it): values kept, none sorts the part; the part's verdict again.
void degrade_measured(PartMeasurement& m, const std::string& why);

}  // namespace hotgauge::measure

namespace hotgauge::measure {

// measure_part in stages, for a cell that wants its answer soon after the last profile: faces are
// added as they become final, and each feature is measured as soon as every face it uses is in
// (a forging's diameter as soon as its first face is, and again if a later face changes it:
// docs/measurement.md "In two steps").
// The same numbers as measure_part on the same inputs, whatever the grouping. `rec`, and the
// scans, displacements, runs and noise given to add_faces, must outlive the measurer.
class PartMeasurer {
  public:
    PartMeasurer(const core::Recipe& recipe, const core::Recording& rec,
                 const Eigen::Isometry3d& T_world_part, const MeasureConfig& config = {});
    ~PartMeasurer();
    PartMeasurer(const PartMeasurer&) = delete;
    PartMeasurer& operator=(const PartMeasurer&) = delete;

    // Prepares faces [first, end) of `rec` (over the cores) with their displacement, untrusted
    // runs and the displacement's own error from `u`, `untrusted` and `noise` (a face absent
    // there: none), then measures the features they complete.
    void add_faces(std::size_t first, std::size_t end, const core::FaceDisplacements& u,
                   const FaceUntrusted& untrusted, const core::FaceDisplacementNoise& noise = {});
    // The features of faces never added are not measured (naming the face); cold values and
    // verdicts for all.
    PartMeasurement finish();

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

// Every feature of `recipe` reported as not measured with `reason` (no pose, no data, ...).
PartMeasurement unmeasured(const core::Recipe& recipe, const core::Recording& rec,
                           const std::string& reason);

}  // namespace hotgauge::measure
