#pragma once
// Press vibration of the sensor head (hub-a.md "Vibration"): damped modes excited by each press
// blow, with a smooth onset, plus a weak ambient hum. Displacement and its second derivative are
// exact (no numerical differentiation), so the simulated accelerometer is consistent with u(t).
#include <Eigen/Core>
#include <cstdint>
#include <random>
#include <vector>

namespace hotgauge::sim {

struct VibrationMode {
    double freq_hz = 8.0;
    double damping_ratio = 0.04;
    double amplitude_mm = 0.6;  // peak displacement one blow excites (before blow-to-blow scatter)
    Eigen::Vector3d direction_world = Eigen::Vector3d::UnitZ();  // unit
};

struct VibrationConfig {
    bool enabled = true;
    std::vector<VibrationMode> modes = {
        {8.0, 0.04, 0.6, Eigen::Vector3d(0.2, 0.1, 1.0).normalized()},
        {23.0, 0.03, 0.25, Eigen::Vector3d(1.0, 0.3, 0.2).normalized()},
        {47.0, 0.02, 0.08, Eigen::Vector3d(0.3, 1.0, 0.1).normalized()},
    };
    double blow_period_s = 2.0;      // press rhythm
    double blow_jitter_s = 0.3;      // uniform ± around the rhythm
    double amplitude_scatter = 0.2;  // relative σ of a blow's strength
    double onset_s = 0.06;           // blows ramp up over about half a period of the 8 Hz mode
    double ambient_rms_mm = 0.002;   // broadband hum, 2–120 Hz
};

// u(t) in world mm for t in seconds on the simulation's time axis.
class Vibration {
  public:
    // Blows are drawn for t in [t_begin_s, t_end_s]; `rng` seeds the blow times and scatter.
    Vibration(const VibrationConfig& config, double t_begin_s, double t_end_s,
              std::mt19937_64& rng);

    Eigen::Vector3d displacement_mm(double t_s) const;
    Eigen::Vector3d acceleration_mmps2(double t_s) const;  // d²u/dt²

  private:
    struct Blow {
        double t_s;
        std::vector<double> amplitude_mm;  // per mode
    };
    struct Hum {
        double freq_hz, amplitude_mm, phase;
        Eigen::Vector3d direction;
    };
    template <class J>
    void evaluate(double t_s, J* out) const;

    VibrationConfig config_;
    std::vector<Blow> blows_;
    std::vector<Hum> hum_;
    double horizon_s_ = 0;  // blows older than this contribute nothing
};

}  // namespace hotgauge::sim
