#include <cmath>

#include "hotgauge/io/yaml_reader.hpp"
#include "hotgauge/sim/simulator.hpp"

namespace hotgauge::sim {
namespace {

using io::YamlReader;

Eigen::Vector3d unit(const YamlReader& y, const YAML::Node& n, const std::string& what) {
    const auto v = y.numbers(n, what, 3);
    Eigen::Vector3d e(v[0], v[1], v[2]);
    if (e.norm() < 1e-9) y.fail(n, what + ": zero vector");
    return e.normalized();
}

double positive(const YamlReader& y, const YAML::Node& map, const std::string& what,
                const char* key, double fallback) {
    const double v = y.number_or(map, what, key, fallback);
    if (!(v > 0.0)) y.fail(map[key] ? map[key] : map, what + "." + key + ": must be positive");
    return v;
}

double fraction(const YamlReader& y, const YAML::Node& map, const std::string& what,
                const char* key, double fallback) {
    const double v = y.number_or(map, what, key, fallback);
    if (v < 0.0 || v > 1.0) y.fail(map[key], what + "." + key + ": must be in [0, 1]");
    return v;
}

// cell.sensor: the laser line sensor as designed.
void read_sensor(const YamlReader& y, const YAML::Node& s, SensorConfig& o) {
    const std::string w = "sensor";
    y.expect_map(s, w,
                 {"width", "pitch_mm", "standoff_mm", "min_range_mm", "max_range_mm",
                  "camera_center_mm", "range_noise_mm", "dropout_fraction", "spike_fraction",
                  "spike_range_mm", "max_incidence_deg", "line_rate_hz", "imager_occlusion"});
    if (s["width"]) o.width = static_cast<int>(y.integer(s["width"], w + ".width"));
    if (o.width < 2) y.fail(s["width"], w + ".width: must be >= 2");
    o.pitch_mm = positive(y, s, w, "pitch_mm", o.pitch_mm);
    o.standoff_mm = positive(y, s, w, "standoff_mm", o.standoff_mm);
    o.min_range_mm = positive(y, s, w, "min_range_mm", o.min_range_mm);
    o.max_range_mm = positive(y, s, w, "max_range_mm", o.max_range_mm);
    if (o.min_range_mm >= o.max_range_mm)
        y.fail(s, w + ": min_range_mm must be below max_range_mm");
    if (s["camera_center_mm"]) {  // the imager seen from the laser origin: [0, baseline, 0]
        const auto v = y.numbers(s["camera_center_mm"], w + ".camera_center_mm", 3);
        if (v[0] != 0.0 || v[2] != 0.0 || !(v[1] > 0.0))
            y.fail(s["camera_center_mm"],
                   w + ".camera_center_mm: expected [0, baseline, 0] with the baseline > 0 (the "
                       "imager beside the laser along the camera's y, as triangulated)");
        o.baseline_mm = v[1];
    }
    if (s["imager_occlusion"])
        o.imager_occlusion = y.boolean(s["imager_occlusion"], w + ".imager_occlusion");
    o.range_noise_mm = y.number_or(s, w, "range_noise_mm", o.range_noise_mm);
    if (o.range_noise_mm < 0) y.fail(s["range_noise_mm"], w + ".range_noise_mm: must be >= 0");
    o.dropout_fraction = fraction(y, s, w, "dropout_fraction", o.dropout_fraction);
    o.spike_fraction = fraction(y, s, w, "spike_fraction", o.spike_fraction);
    o.spike_range_mm = positive(y, s, w, "spike_range_mm", o.spike_range_mm);
    o.max_incidence_deg = positive(y, s, w, "max_incidence_deg", o.max_incidence_deg);
    o.line_rate_hz = positive(y, s, w, "line_rate_hz", o.line_rate_hz);
}

// cell.faces[i]: one face's geometry; `earlier` are the faces before it (names are unique).
FaceConfig read_face(const YamlReader& y, const YAML::Node& f, std::size_t i,
                     const std::vector<FaceConfig>& earlier) {
    const std::string w = "faces[" + std::to_string(i) + "]";
    y.expect_map(f, w,
                 {"name", "camera_to_world", "scan_direction", "accel_to_camera", "scan_length_mm",
                  "profile_spacing_mm", "support_visible"});
    FaceConfig fc;
    fc.name = y.string(y.require(f, w, "name"), w + ".name");
    for (const auto& other : earlier)
        if (other.name == fc.name) y.fail(f, w + ".name: duplicate face '" + fc.name + "'");
    fc.T_world_camera = y.isometry(y.require(f, w, "camera_to_world"), w + ".camera_to_world");
    fc.scan_direction = unit(y, y.require(f, w, "scan_direction"), w + ".scan_direction");
    if (f["accel_to_camera"])
        fc.R_camera_accel = y.rotation(f["accel_to_camera"], w + ".accel_to_camera");
    fc.scan_length_mm = positive(y, f, w, "scan_length_mm", fc.scan_length_mm);
    fc.profile_spacing_mm = positive(y, f, w, "profile_spacing_mm", fc.profile_spacing_mm);
    if (f["support_visible"])
        fc.support_visible = y.boolean(f["support_visible"], w + ".support_visible");
    return fc;
}

// cell.vibration.modes[i]: one damped mode of the press.
VibrationMode read_vibration_mode(const YamlReader& y, const YAML::Node& n, const std::string& wm) {
    y.expect_map(n, wm, {"freq_hz", "damping_ratio", "amplitude_mm", "direction"});
    VibrationMode m;
    m.freq_hz = positive(y, n, wm, "freq_hz", m.freq_hz);
    m.damping_ratio = fraction(y, n, wm, "damping_ratio", m.damping_ratio);
    m.amplitude_mm = y.number(y.require(n, wm, "amplitude_mm"), wm + ".amplitude_mm");
    m.direction_world = unit(y, y.require(n, wm, "direction"), wm + ".direction");
    return m;
}

// cell.vibration: the press blows and their modes.
void read_vibration(const YamlReader& y, const YAML::Node& v, VibrationConfig& o) {
    const std::string w = "vibration";
    y.expect_map(v, w,
                 {"enabled", "modes", "blow_period_s", "blow_jitter_s", "amplitude_scatter",
                  "onset_s", "ambient_rms_mm"});
    if (v["enabled"]) o.enabled = y.boolean(v["enabled"], w + ".enabled");
    o.blow_period_s = positive(y, v, w, "blow_period_s", o.blow_period_s);
    o.blow_jitter_s = y.number_or(v, w, "blow_jitter_s", o.blow_jitter_s);
    o.amplitude_scatter = y.number_or(v, w, "amplitude_scatter", o.amplitude_scatter);
    o.onset_s = positive(y, v, w, "onset_s", o.onset_s);
    o.ambient_rms_mm = y.number_or(v, w, "ambient_rms_mm", o.ambient_rms_mm);
    if (const YAML::Node ms = v["modes"]) {
        if (!ms.IsSequence()) y.fail(ms, w + ".modes: expected a list");
        o.modes.clear();
        for (std::size_t i = 0; i < ms.size(); ++i)
            o.modes.push_back(
                read_vibration_mode(y, ms[i], w + ".modes[" + std::to_string(i) + "]"));
    }
}

// cell.accelerometer: the head's accelerometer.
void read_accelerometer(const YamlReader& y, const YAML::Node& a, AccelConfig& o) {
    const std::string w = "accelerometer";
    y.expect_map(a, w,
                 {"rate_hz", "noise_density_ug", "bias_mps2", "range_g", "margin_s", "jitter_ns"});
    o.rate_hz = positive(y, a, w, "rate_hz", o.rate_hz);
    o.noise_density_ug = y.number_or(a, w, "noise_density_ug", o.noise_density_ug);
    o.bias_mps2 = y.number_or(a, w, "bias_mps2", o.bias_mps2);
    o.range_g = positive(y, a, w, "range_g", o.range_g);
    o.margin_s = y.number_or(a, w, "margin_s", o.margin_s);
    o.jitter_ns = y.number_or(a, w, "jitter_ns", o.jitter_ns);
    if (o.noise_density_ug < 0 || o.bias_mps2 < 0 || o.margin_s < 0 || o.jitter_ns < 0)
        y.fail(a, w + ": noise_density_ug, bias_mps2, margin_s and jitter_ns must be >= 0");
}

}  // namespace

core::Result<CellConfig> read_cell_config(const std::filesystem::path& file) {
    const YamlReader y(file.string());
    return y.guarded<CellConfig>([&] {
        const YAML::Node root = y.load();
        y.expect_map(root, "cell",
                     {"sensor", "faces", "vibration", "accelerometer", "placement",
                      "support_half_size_mm", "face_gap_s"});
        CellConfig c;
        c.support_half_size_mm =
            positive(y, root, "cell", "support_half_size_mm", c.support_half_size_mm);
        c.face_gap_s = positive(y, root, "cell", "face_gap_s", c.face_gap_s);

        if (const YAML::Node s = root["sensor"]) read_sensor(y, s, c.sensor);

        const YAML::Node faces = y.require(root, "cell", "faces");
        if (!faces.IsSequence() || faces.size() == 0)
            y.fail(faces, "faces: expected a non-empty list");
        for (std::size_t i = 0; i < faces.size(); ++i)
            c.faces.push_back(read_face(y, faces[i], i, c.faces));

        if (const YAML::Node v = root["vibration"]) read_vibration(y, v, c.vibration);
        if (const YAML::Node a = root["accelerometer"]) read_accelerometer(y, a, c.accel);
        if (const YAML::Node p = root["placement"]) {
            y.expect_map(p, "placement", {"max_offset_mm", "max_tilt_deg"});
            c.placement.max_offset_mm =
                y.number_or(p, "placement", "max_offset_mm", c.placement.max_offset_mm);
            c.placement.max_tilt_deg =
                y.number_or(p, "placement", "max_tilt_deg", c.placement.max_tilt_deg);
        }
        return c;
    });
}

}  // namespace hotgauge::sim
