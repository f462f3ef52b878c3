#pragma once
// Vibration compensation (seed paper §4.1, Eq. 5–7): the accelerometer in the sensor head,
// integrated twice in the frequency domain, gives the head's displacement u(t); every profile is
// moved back by it (P = P_nominal + u(t_k), recording-format-v1). docs/compensation.md.
#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "hotgauge/core/recording.hpp"

namespace hotgauge::compensate {

struct CompensationConfig {
    double highpass_hz = 1.5;     // below this nothing is trusted (noise grows as 1/f²)
    int highpass_order = 4;       // Butterworth magnitude order of the zero-phase high-pass
    double taper_s = 0.25;        // Tukey taper at each end of the record (inside the margins)
    double min_margin_s = 0.5;    // profiles closer than this to a record end are untrusted
    double clock_offset_s = 0.0;  // accelerometer clock − camera clock
    double gap_factor = 3.0;      // a sample interval above gap_factor × nominal is a gap
    double clip_mps2 = 8.0 * 9.80665 * 0.999;  // |a| at or above this on any axis: clipped
    // Profiles this close to a gap, a clipped or a non-finite sample are untrusted: there the
    // bridge leaves u off by 43 µm per axis (hole_sigma_mm), beyond what a feature's u can carry.
    // Farther out, hole_sigma_mm is a term of each feature's u (docs/compensation.md "Holes in
    // u"; it was 0.5 s before that term, which left every feature degraded at 2 % loss).
    double degrade_pad_s = 0.05;
    // What the bridge leaves of u per world axis by the distance from a hole: rows (distance up
    // to s, σ mm). RMS of |u_est − u_true| over the three axes by the distance from the nearest
    // 10 ms hole, the same without loss taken out in quadrature, / √3; per row the larger of two
    // measurements (docs/compensation.md "Holes in u"): the independent simulator's truth
    // (tests/bench/hole_bridge_study.py, independent-paper-7, 2 % loss, 4 patterns × 4 faces) and
    // ours (CompensateFace.RandomHolesErrorByDistance, which checks the rows beyond the pad).
    std::vector<std::array<double, 2>> hole_sigma_mm = {
        {0.05, 0.0433}, {0.1, 0.0177}, {0.2, 0.0078}, {0.3, 0.0036}, {0.5, 0.0034}, {0.6, 0.0015}};
    // The support plate (world z = 0 after commissioning) as a displacement sensor: a profile
    // with at least plate_min_points samples within plate_band_mm of it, once the
    // accelerometer's u is applied, takes u_z = −(median of their nominal world z), without
    // integration, lost datagrams or not (docs/compensation.md "The support plate").
    bool plate_z = true;
    double plate_band_mm = 1.0;
    int plate_min_points = 50;
    // A longer hole in the record (lost datagrams, clipping) is not bridged within the error
    // budget beyond the pad: every profile of the face is untrusted. Measured in the same test.
    double max_bridge_s = 0.06;
};

// Displacement from uniformly sampled acceleration (one axis, SI units in, same units·s² out):
// mean removed, Tukey taper, zero padding to ≥ 2N, X(k)/(jω_k)² with a smooth
// zero-phase high-pass and the DC bin zeroed, inverse DFT (OpenCV). Returns N samples.
std::vector<double> integrate_twice(const std::vector<double>& accel, double rate_hz,
                                    const CompensationConfig& config);

// The accelerometer's noise density per world axis ((m/s²)²/Hz, one-sided), read off the
// record's top band, [0.3, 0.45] × the rate, far above any press mode: the median of a
// Hann-windowed periodogram of 256-sample segments (overlapping by half, none across a break:
// sample i and i + 1 for i in `breaks`, a gap) over that band, over ln 2 (the median of an
// exponential variable). A press blow's broadband burst is in few segments and the median passes
// it by; what is left of it makes the density larger. A sensor's own output filter rolling off in
// that band would make it smaller: docs/compensation.md "Its own error". Zero when fewer than 4
// segments fit.
std::array<double, 3> accel_noise_density(const std::array<std::vector<double>, 3>& accel_world,
                                          double rate_hz,
                                          const std::vector<std::size_t>& breaks = {});

// The displacement error that noise of density s_a leaves after integrate_twice: autocovariance
// ∫ s_a·hp(f)²/(2πf)⁴·cos(2πfτ) df per world axis, at lags of 10 ms up to 2.5 s, in mm². White
// noise is assumed: a sensor's 1/f noise and bias drift below the high-pass are not in it.
core::DisplacementNoise displacement_noise(const std::array<double, 3>& density_si,
                                           const CompensationConfig& config);

struct FaceCompensation {
    std::string face;
    bool applied = false;              // displacement_mm is valid for (most) profiles
    bool degraded = false;             // some profiles could not be compensated reliably
    std::vector<std::string> reasons;  // why degraded / not applied
    std::vector<Eigen::Vector3d> displacement_mm;  // per profile, world frame (0 where not applied)
    std::vector<std::uint8_t> profile_degraded;    // per profile: 1 = untrusted
    std::int64_t n_degraded = 0;
    std::vector<core::UntrustedProfiles> untrusted;  // the same as runs, with their cause
    double peak_mm = 0.0, rms_mm = 0.0;              // of |u| over the profiles
    double rate_hz = 0.0;                            // resampling rate used
    // Profiles whose u_z the support plate gave (CompensationConfig::plate_z), and the median
    // standard error of their plate medians.
    std::int64_t plate_profiles = 0;
    double plate_sigma_mm = 0.0;
};

// Per-profile world displacement of one face's sensor. Never throws: bad or missing samples make
// the result degraded (with reasons and the untrusted profiles), not an error. Gaps, and the
// non-finite and clipped samples left out, are bridged: the velocity and position change the
// straight-line fill got wrong across each is estimated by least squares (docs/compensation.md
// "Gaps").
FaceCompensation compensate_face(const core::FaceScan& face, const CompensationConfig& config);

// What compensate_face's displacement of `face` may be off by: the accelerometer's noise density
// per world axis (accel_noise_density, off the samples as they came, segments stopping at gaps)
// and the error it leaves (displacement_noise). Not known (noise.known() false, densities 0)
// when the record is too short to tell. Apart from compensate_face: only the measurement wants
// it, not the clock-offset search or the pose's look at a record still growing.
struct CompensationError {
    std::array<double, 3> accel_noise_ug = {0, 0, 0};  // µg/√Hz
    core::DisplacementNoise noise;
};
CompensationError compensation_error(const core::FaceScan& face, const CompensationConfig& config);

}  // namespace hotgauge::compensate
