#include "hotgauge/calib/calibration.hpp"

#include <algorithm>
#include <cmath>

#include "hotgauge/io/yaml_reader.hpp"
#include "hotgauge/io/yaml_writer.hpp"

namespace hotgauge::calib {
namespace {

using io::YamlReader;

constexpr const char* kFormat = "hotgauge-calibration-1";
// A plane normal or scan direction read is a unit vector when its norm is within this of 1 (not
// measured).
constexpr double kUnitTolerance = 1e-6;

double positive(const YamlReader& y, const YAML::Node& map, const std::string& what,
                const char* key) {
    const double v = y.number(y.require(map, what, key), what + "." + key);
    if (!(v > 0.0)) y.fail(map[key], what + "." + key + ": must be positive");
    return v;
}

// sensor: {model: pinhole, width, height, fx, fy, cx, cy, distortion: [k1, k2, p1, p2, k3],
// plane_normal: [x, y, z], plane_offset_mm}: an image-mode calibration.
SensorModel read_pinhole(const YamlReader& y, const YAML::Node& s) {
    const std::string w = "sensor";
    y.expect_map(s, w,
                 {"model", "width", "height", "fx", "fy", "cx", "cy", "distortion", "plane_normal",
                  "plane_offset_mm"});
    SensorModel m;
    m.model = "pinhole";
    PinholeCamera& c = m.camera;
    c.width = static_cast<int>(y.integer(y.require(s, w, "width"), w + ".width"));
    c.height = static_cast<int>(y.integer(y.require(s, w, "height"), w + ".height"));
    if (c.width < 2 || c.height < 2) y.fail(s, w + ": width and height must be >= 2");
    m.width = c.width;
    c.fx = positive(y, s, w, "fx");
    c.fy = positive(y, s, w, "fy");
    c.cx = y.number(y.require(s, w, "cx"), w + ".cx");
    c.cy = y.number(y.require(s, w, "cy"), w + ".cy");
    const auto d = y.numbers(y.require(s, w, "distortion"), w + ".distortion", 5);
    std::copy(d.begin(), d.end(), c.distortion.begin());
    const YAML::Node n = y.require(s, w, "plane_normal");
    const auto v = y.numbers(n, w + ".plane_normal", 3);
    m.plane.normal = Eigen::Vector3d(v[0], v[1], v[2]);
    if (std::abs(m.plane.normal.norm() - 1.0) > kUnitTolerance)
        y.fail(n, w + ".plane_normal: must be a unit vector");
    m.plane.offset_mm = positive(y, s, w, "plane_offset_mm");
    return m;
}

// sensor: {model: stage, width, height, degree, x_degree, u0_px, x_pitch_mm,
// reference_range_mm, coefficients: [width × (degree + 2)], x_coefficients: [width ×
// (x_degree + 1)]}: a stage calibration's pixel → mm map (acquire::CalibratedModel).
SensorModel read_stage_map(const YamlReader& y, const YAML::Node& s) {
    const std::string w = "sensor";
    y.expect_map(s, w,
                 {"model", "width", "height", "degree", "x_degree", "u0_px", "x_pitch_mm",
                  "reference_range_mm", "coefficients", "x_coefficients"});
    SensorModel m;
    m.model = "stage";
    acquire::CalibratedModel& c = m.map;
    auto integer = [&](const char* key, int lo, int hi) {
        const auto v = y.integer(y.require(s, w, key), w + "." + key);
        if (v < lo || v > hi)
            y.fail(s[key], w + "." + key + ": must be in [" + std::to_string(lo) + ", " +
                               std::to_string(hi) + "]");
        return static_cast<int>(v);
    };
    c.width_px = integer("width", 2, 1 << 15);
    c.height_px = integer("height", 2, 1 << 15);
    c.degree = integer("degree", 1, 5);
    c.x_degree = integer("x_degree", 0, 5);
    m.width = c.width_px;
    c.u0_px = y.number(y.require(s, w, "u0_px"), w + ".u0_px");
    c.x_pitch_mm = positive(y, s, w, "x_pitch_mm");
    c.reference_range_mm = positive(y, s, w, "reference_range_mm");
    c.coefficients = y.numbers(y.require(s, w, "coefficients"), w + ".coefficients",
                               static_cast<std::size_t>(c.width_px) * (c.degree + 2));
    c.x_coefficients =
        y.numbers(y.require(s, w, "x_coefficients"), w + ".x_coefficients",
                  c.x_degree > 0 ? static_cast<std::size_t>(c.width_px) * (c.x_degree + 1) : 0);
    if (auto ok = acquire::Triangulation::calibrated(c); !ok)
        y.fail(s, w + ": " + ok.error().message);
    return m;
}

SensorModel read_sensor(const YamlReader& y, const YAML::Node& s) {
    const std::string w = "sensor";
    const std::string model = y.string(y.require(s, w, "model"), w + ".model");
    if (model == "pinhole") return read_pinhole(y, s);
    if (model == "stage") return read_stage_map(y, s);
    if (model != "direct_beam")
        y.fail(s["model"],
               w + ".model: '" + model + "' is not known (direct_beam, pinhole, stage)");
    y.expect_map(s, w,
                 {"model", "width", "pitch_mm", "standoff_mm", "min_range_mm", "max_range_mm",
                  "baseline_mm"});
    SensorModel m;
    m.width = static_cast<int>(y.integer(y.require(s, w, "width"), w + ".width"));
    if (m.width < 2) y.fail(s["width"], w + ".width: must be >= 2");
    m.pitch_mm = positive(y, s, w, "pitch_mm");
    m.standoff_mm = positive(y, s, w, "standoff_mm");
    m.min_range_mm = positive(y, s, w, "min_range_mm");
    m.max_range_mm = positive(y, s, w, "max_range_mm");
    if (m.min_range_mm >= m.max_range_mm)
        y.fail(s, w + ": min_range_mm must be below max_range_mm");
    m.baseline_mm = positive(y, s, w, "baseline_mm");
    return m;
}

FaceCalibration read_face(const YamlReader& y, const YAML::Node& f, const std::string& w) {
    y.expect_map(f, w,
                 {"name", "camera_to_world", "scan_direction", "travel_scale", "accel_to_camera",
                  "recorded_camera_to_world"});
    FaceCalibration g;
    g.name = y.string(y.require(f, w, "name"), w + ".name");
    g.T_world_camera = y.isometry(y.require(f, w, "camera_to_world"), w + ".camera_to_world");
    const YAML::Node d = y.require(f, w, "scan_direction");
    const auto v = y.numbers(d, w + ".scan_direction", 3);
    g.scan_direction = Eigen::Vector3d(v[0], v[1], v[2]);
    if (std::abs(g.scan_direction.norm() - 1.0) > kUnitTolerance)
        y.fail(d, w + ".scan_direction: must be a unit vector");
    g.travel_scale = positive(y, f, w, "travel_scale");
    g.R_camera_accel = y.rotation(y.require(f, w, "accel_to_camera"), w + ".accel_to_camera");
    if (const YAML::Node r = f["recorded_camera_to_world"])
        g.recorded_camera_to_world = y.isometry(r, w + ".recorded_camera_to_world");
    return g;
}

// A matrix as a flow sequence of rows.
std::string fmt_matrix(const Eigen::MatrixXd& m) {
    std::string out = "[";
    for (Eigen::Index r = 0; r < m.rows(); ++r) {
        const Eigen::RowVectorXd row = m.row(r);
        out += (r ? ", " : "") + io::fmt_row(row.data(), static_cast<int>(row.size()));
    }
    return out + "]";
}

// The sensor block as one flow map.
std::string fmt_sensor(const SensorModel& s) {
    using io::fmt_double;
    if (s.model == "pinhole") {
        const PinholeCamera& c = s.camera;
        return "{model: pinhole, width: " + std::to_string(c.width) +
               ", height: " + std::to_string(c.height) + ", fx: " + fmt_double(c.fx) +
               ", fy: " + fmt_double(c.fy) + ", cx: " + fmt_double(c.cx) +
               ", cy: " + fmt_double(c.cy) +
               ", distortion: " + io::fmt_row(c.distortion.data(), 5) +
               ", plane_normal: " + io::fmt_row(s.plane.normal.data(), 3) +
               ", plane_offset_mm: " + fmt_double(s.plane.offset_mm) + "}";
    }
    if (s.model == "stage") {
        const acquire::CalibratedModel& c = s.map;
        const auto row = [](const std::vector<double>& v) {
            return io::fmt_row(v.data(), static_cast<int>(v.size()));
        };
        return "{model: stage, width: " + std::to_string(c.width_px) +
               ", height: " + std::to_string(c.height_px) +
               ", degree: " + std::to_string(c.degree) +
               ", x_degree: " + std::to_string(c.x_degree) + ", u0_px: " + fmt_double(c.u0_px) +
               ", x_pitch_mm: " + fmt_double(c.x_pitch_mm) +
               ", reference_range_mm: " + fmt_double(c.reference_range_mm) +
               ",\n         coefficients: " + row(c.coefficients) +
               ",\n         x_coefficients: " + row(c.x_coefficients) + "}";
    }
    return "{model: direct_beam, width: " + std::to_string(s.width) +
           ", pitch_mm: " + fmt_double(s.pitch_mm) + ", standoff_mm: " + fmt_double(s.standoff_mm) +
           ", min_range_mm: " + fmt_double(s.min_range_mm) +
           ", max_range_mm: " + fmt_double(s.max_range_mm) +
           ", baseline_mm: " + fmt_double(s.baseline_mm) + "}";
}

}  // namespace

const FaceCalibration* Calibration::face(const std::string& name) const {
    for (const auto& f : faces)
        if (f.name == name) return &f;
    return nullptr;
}

core::Result<Calibration> parse_calibration(std::string_view text,
                                            const std::filesystem::path& file) {
    const YamlReader y(file.string(), text);
    return y.guarded<Calibration>([&] {
        const YAML::Node root = y.load();
        const std::string w = "calibration";
        y.expect_map(root, w,
                     {"format", "calibrated_at", "method", "source", "residuals", "sensor",
                      "clock_offset_ns", "accel_bias_mps2", "faces"});
        const std::string format = y.string(y.require(root, w, "format"), "format");
        if (format != kFormat)
            y.fail(root["format"], "format: '" + format + "', expected " + kFormat);
        Calibration c;
        c.calibrated_at = y.string(y.require(root, w, "calibrated_at"), "calibrated_at");
        c.method = y.string(y.require(root, w, "method"), "method");
        c.source = y.string(y.require(root, w, "source"), "source");
        if (const YAML::Node r = root["residuals"]) {
            if (!r.IsMap()) y.fail(r, "residuals: expected a mapping");
            for (const auto& kv : r)
                c.residuals[kv.first.as<std::string>()] =
                    y.number(kv.second, "residuals." + kv.first.as<std::string>());
        }
        c.sensor = read_sensor(y, y.require(root, w, "sensor"));
        c.clock_offset_ns = y.integer(y.require(root, w, "clock_offset_ns"), "clock_offset_ns");
        const auto b = y.numbers(y.require(root, w, "accel_bias_mps2"), "accel_bias_mps2", 3);
        c.accel_bias_mps2 = Eigen::Vector3d(b[0], b[1], b[2]);
        const YAML::Node faces = y.require(root, w, "faces");
        if (!faces.IsSequence() || faces.size() == 0)
            y.fail(faces, "faces: expected a non-empty list");
        for (std::size_t i = 0; i < faces.size(); ++i) {
            const std::string wf = "faces[" + std::to_string(i) + "]";
            FaceCalibration g = read_face(y, faces[i], wf);
            if (c.face(g.name)) y.fail(faces[i], wf + ".name: duplicate face '" + g.name + "'");
            c.faces.push_back(std::move(g));
        }
        return c;
    });
}

core::Result<Calibration> read_calibration(const std::filesystem::path& file) {
    return io::parse_file(file, parse_calibration);
}

core::Result<void> write_calibration(const Calibration& c, const std::filesystem::path& file) {
    using io::fmt_double, io::fmt_row, io::quote;
    std::string y = "# The cell's measured geometry (docs/calibration.md).\n";
    y += std::string("format: ") + kFormat + "\ncalibrated_at: " + quote(c.calibrated_at) +
         "\nmethod: " + quote(c.method) + "\nsource: " + quote(c.source) + "\nresiduals: {";
    bool first = true;
    for (const auto& [key, value] : c.residuals) {
        y += (first ? "" : ", ") + quote(key) + ": " + fmt_double(value);
        first = false;
    }
    y += "}\nsensor: " + fmt_sensor(c.sensor) + "\n";
    y += "clock_offset_ns: " + std::to_string(c.clock_offset_ns) +
         "\naccel_bias_mps2: " + fmt_row(c.accel_bias_mps2.data(), 3) + "\nfaces:\n";
    for (const auto& f : c.faces) {
        y += "  - name: " + quote(f.name) +
             "\n    camera_to_world: " + fmt_matrix(f.T_world_camera.matrix()) +
             "\n    scan_direction: " + fmt_row(f.scan_direction.data(), 3) +
             "\n    travel_scale: " + fmt_double(f.travel_scale) +
             "\n    accel_to_camera: " + fmt_matrix(f.R_camera_accel) + "\n";
        if (f.recorded_camera_to_world)
            y += "    recorded_camera_to_world: " +
                 fmt_matrix(f.recorded_camera_to_world->matrix()) + "\n";
    }
    return io::write_text(file, y);
}

namespace {

// The calibrated pose of a face whose face.yaml says `recorded` (apply_geometry's rule).
Eigen::Isometry3d pose_for(const FaceCalibration& g, const core::FaceScan& f) {
    if (f.geometry_from_calibration || !g.recorded_camera_to_world) return g.T_world_camera;
    return f.T_world_camera * g.recorded_camera_to_world->inverse() * g.T_world_camera;
}

}  // namespace

core::Result<void> apply_geometry(const Calibration& c, const std::string& calibration_file,
                                  core::Recording& recording) {
    for (const auto& f : recording.faces)
        if (!c.face(f.name))
            return core::make_error(calibration_file + ": no face '" + f.name +
                                    "' (the recording has it)");
    for (auto& f : recording.faces) {
        const FaceCalibration& g = *c.face(f.name);
        const Eigen::Isometry3d T_world_camera = pose_for(g, f);
        const double rescale = g.travel_scale / f.travel_scale;
        for (double& p : f.profile_positions_mm) p *= rescale;
        const std::int64_t shift = c.clock_offset_ns - f.clock_offset_ns;
        for (std::int64_t& t : f.profile_times_ns) t += shift;
        f.geometry() = g.geometry();
        f.T_world_camera = T_world_camera;  // a head placed per part keeps its placement
        f.clock_offset_ns = c.clock_offset_ns;
    }
    return {};
}

core::Result<acquire::ScanConfig> scan_config(const Calibration& c, const std::string& face,
                                              acquire::ScanConfig scan) {
    const FaceCalibration* g = c.face(face);
    if (!g) return core::make_error("no face '" + face + "' in the calibration");
    scan.face = g->geometry();
    scan.clock_offset_ns = c.clock_offset_ns;
    scan.geometry_from_calibration = true;
    return scan;
}

core::Result<acquire::Triangulation> triangulation(const SensorModel& s, int height_px) {
    if (s.model == "stage") {
        if (s.map.height_px != height_px)
            return core::make_error("sensor: the calibration's map has " +
                                    std::to_string(s.map.height_px) + " rows, the camera " +
                                    std::to_string(height_px));
        return acquire::Triangulation::calibrated(s.map);
    }
    if (s.model == "pinhole") {
        if (s.camera.height != height_px)
            return core::make_error("sensor: the calibration's camera has " +
                                    std::to_string(s.camera.height) + " rows, the camera " +
                                    std::to_string(height_px));
        SensorCalibration calibration;
        calibration.camera = s.camera;
        calibration.plane = s.plane;
        auto fit = fit_triangulation(calibration);
        if (!fit) return core::make_error("sensor: " + fit.error().message);
        return acquire::Triangulation::calibrated(fit->model);
    }
    acquire::DirectBeamDesign d;
    d.design() = s.design();
    d.height_px = height_px;
    auto params = acquire::design_direct_beam(d);
    if (!params) return params.error();
    return acquire::Triangulation::direct_beam(*params);
}

}  // namespace hotgauge::calib
