#pragma once
// Triangulation (docs/acquisition.md "Triangulation"): image (column u, sub-pixel row v) →
// camera-frame profile point (x, z) mm in the laser plane (the camera's y = 0 plane) and back.
// Image coordinates are full-sensor pixels with pixel centres at integers; the field is
// u ∈ [−0.5, width − 0.5], v ∈ [−0.5, height − 0.5]. Rows increase with range.
#include <cstdint>
#include <span>
#include <utility>
#include <variant>
#include <vector>

#include "hotgauge/acquire/stripe.hpp"
#include "hotgauge/core/result.hpp"

namespace hotgauge::acquire {

// The paper's direct-beam sensor (§2): the laser along the surface normal, the imaging lens at
// angle α to it, the imager tilted at β to the lens axis. Eq. 1 (Scheimpflug): a0·tanα = b0·tanβ.
// Eq. 2: y = a0·x·sinβ / (b0·sinα − x·sin(α + β)), x the spot image's shift on the imager (along
// its rows), y the spot's shift along the laser. Here z = reference_range_mm + y with
// x = (v − v0_px)·pixel_size_mm, and every column is one ray of the laser fan:
// x_mm = (u − u0_px)·x_pitch_mm·z/reference_range_mm.
struct DirectBeamParams {
    double a0_mm = 0.0;               // reference spot to the lens (object side)
    double b0_mm = 0.0;               // lens to the reference spot's image (image side)
    double alpha_deg = 0.0;           // lens axis to the laser
    double beta_deg = 0.0;            // lens axis to the imager surface
    double pixel_size_mm = 0.0;       // pixel pitch along the imager's rows
    double v0_px = 0.0;               // row of the reference spot's image
    double u0_px = 0.0;               // column of the fan's central ray
    double x_pitch_mm = 0.0;          // x per column at the reference range
    double reference_range_mm = 0.0;  // z of the reference spot
    int width_px = 0, height_px = 0;  // the imager (the field)
};

// Calibrated model: per column c, z = (p0 + p1·t + … + pn·tⁿ) / (1 + q·t) with
// t = (v − (height − 1)/2) / ((height − 1)/2), n ≤ 5; the direct-beam law is this with n = 1
// (a polynomial alone cannot follow its pole: degree 5 leaves 75 µm over 600–1200 mm). Between
// columns z is interpolated linearly. x from the fan as in the direct-beam model, or, with
// x_degree m > 0, per column x = z·(s0 + s1·t + … + sm·tᵐ) (a lens's distortion bends a column
// off the fan's ray), interpolated between columns alike; x/z must grow with the column.
struct CalibratedModel {
    int width_px = 0, height_px = 0;
    int degree = 0;                    // n
    std::vector<double> coefficients;  // width_px × (n + 2): p0 … pn, q per column
    double u0_px = 0.0, x_pitch_mm = 0.0, reference_range_mm = 0.0;
    int x_degree = 0;                    // m; 0: x from the fan
    std::vector<double> x_coefficients;  // width_px × (m + 1): s0 … sm per column, when m > 0
};

struct ProfilePoint {
    double x_mm, z_mm;  // NaN, NaN: outside the field
};
struct ImagePoint {
    double u_px, v_px;  // NaN, NaN: does not image into the field
};

// One sensor's image ↔ laser-plane mapping. Immutable after construction; thread-safe.
class Triangulation {
  public:
    // Errors name the offending parameter.
    static core::Result<Triangulation> direct_beam(const DirectBeamParams& params);
    static core::Result<Triangulation> calibrated(CalibratedModel model);

    ProfilePoint to_camera(double u_px, double v_px) const;
    ImagePoint to_image(double x_mm, double z_mm) const;
    // One profile at once (what triangulate() runs on): point i is column i + column_offset_px,
    // out gets x, z per point (NaN, NaN unless kOk or outside the field). Same values as
    // to_camera, without its per-point dispatch.
    void to_camera(std::span<const StripePoint> profile, double column_offset_px,
                   double row_offset_px, float* out_xz) const;

    int width_px() const { return width_; }
    int height_px() const { return height_; }

  private:
    struct DirectBeam {
        DirectBeamParams p;
        double sin_a, sin_b, sin_ab;
    };
    using Model = std::variant<DirectBeam, CalibratedModel>;
    Triangulation(Model model, int width, int height)
        : model_(std::move(model)), width_(width), height_(height) {}
    Model model_;
    int width_, height_;
};

// Appends one profile (x, z per point, NaN unless kOk) to `profiles_mm` in core::FaceScan's
// layout. Point i is column i + column_offset_px; rows get row_offset_px (the camera's region
// offsets, for full-sensor coordinates).
void triangulate(const Triangulation& triangulation, std::span<const StripePoint> profile,
                 std::vector<float>& profiles_mm, double column_offset_px = 0.0,
                 double row_offset_px = 0.0);

// Calibration samples: a stripe point (u, v) and where it truly is in the laser plane.
struct CalibrationSample {
    double u_px, v_px, x_mm, z_mm;
};
struct CalibrationOptions {
    int width_px = 2048, height_px = 1088;
    int degree = 3;                     // numerator degree n, 1..5
    double reference_range_mm = 890.0;  // where x_pitch_mm is quoted
    int x_degree = 0;                   // 0: x from the fan; 1..5: x/z per column in t
};
struct CalibrationFit {
    CalibratedModel model;
    double rms_z_mm = 0.0, max_abs_z_mm = 0.0;  // residuals of z over the samples
    double rms_x_mm = 0.0;
};
// Least squares per column (samples grouped by their nearest column; each column needs
// degree + 2 samples at distinct rows), re-weighted once so that z residuals, not
// (1 + q·t)·z residuals, are minimised; u0 and the pitch from all samples' x, and with
// x_degree > 0 each column's x/z law (least squares on x).
core::Result<CalibrationFit> fit_calibrated_model(std::span<const CalibrationSample> samples,
                                                  const CalibrationOptions& options);

// A line-laser head as designed: the laser fan in the camera's y = 0 plane from the camera
// origin, ray i at x_i = (i − (width − 1)/2)·pitch on the plane z = standoff, the imager
// `baseline_mm` beside the laser origin along the camera's y. The one place the design numbers
// live (paper §3.3: 2048 rays, 0.2 mm at 890 mm, range 600–1200 mm, 300 mm baseline): the
// simulator's sensor (sim::SensorConfig), the calibration's model (calib::SensorModel) and the
// direct-beam triangulation (DirectBeamDesign) all hold one.
struct SensorDesign {
    int width = 2048;             // rays, one per imager column
    double pitch_mm = 0.2;        // ray spacing at the standoff
    double standoff_mm = 890.0;   // lens working distance
    double min_range_mm = 600.0;  // measuring range along z_camera
    double max_range_mm = 1200.0;
    double baseline_mm = 300.0;  // imager centre from the laser origin, along camera y

    SensorDesign& design() { return *this; }
    const SensorDesign& design() const { return *this; }
};

// The design on a Photonfocus MV1-D2048-3D03 imager (2048 × 1088, 5.5 µm): a0 and α from the
// baseline and standoff, b0 and v0 such that rows 0 and height − 1 see the range's ends, β from
// Eq. 1.
struct DirectBeamDesign : SensorDesign {
    int height_px = 1088;
    double pixel_size_mm = 0.0055;
};
core::Result<DirectBeamParams> design_direct_beam(const DirectBeamDesign& design);

}  // namespace hotgauge::acquire
