// calib: calibration.yaml read back to the same numbers it was written with, every malformed
// field refused with file:line and the key, the shipped config/calibration.yaml equal to the
// nominal geometry of config/cell.yaml (the virtual cell before commissioning), and the
// triangulation built from the sensor model the same as the simulator's.
#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

#include "hotgauge/calib/calibration.hpp"
#include "hotgauge/io/recording_io.hpp"
#include "hotgauge/sim/geometry.hpp"
#include "hotgauge/sim/simulator.hpp"
#include "hotgauge/vcell/render.hpp"
#include "temp_dir.hpp"

namespace calib = hotgauge::calib;
namespace sim = hotgauge::sim;
namespace vcell = hotgauge::vcell;

namespace {

const std::string kConfig = HOTGAUGE_SOURCE_DIR "/config";

calib::Calibration example() {
    calib::Calibration c;
    c.calibrated_at = "2026-12-02T06:00:00Z";
    c.method = "artifact";
    c.source = "spheres \"A\" v2";
    c.residuals = {{"sphere_rms_mm", 0.0031}, {"scale_ppm", -12.5}};
    c.sensor.baseline_mm = 301.25;
    c.clock_offset_ns = -1'234'567;
    c.accel_bias_mps2 = {0.01, -0.002, 0.0071};
    for (const char* name : {"top", "side1"}) {
        calib::FaceCalibration g;
        g.name = name;
        g.T_world_camera = Eigen::Translation3d(1.0 / 3.0, -120.0, 930.0) *
                           Eigen::AngleAxisd(0.1234, Eigen::Vector3d(1, 2, 3).normalized());
        g.scan_direction = Eigen::Vector3d(0.001, 1.0, -0.0003).normalized();
        g.travel_scale = 1.0 + 1.0 / 7.0 * 1e-3;
        g.R_camera_accel = Eigen::AngleAxisd(0.05, Eigen::Vector3d::UnitZ()).toRotationMatrix();
        c.faces.push_back(g);
    }
    return c;
}

std::string text_of(const std::filesystem::path& p) {
    std::ifstream in(p);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
}

// A one-face recording ("top", one ray per profile, gravity on two accelerometer samples either
// side of the profiles) for the geometry keys and their round trip through the files.
hotgauge::core::Recording top_face_recording(std::vector<float> profiles_mm,
                                             std::vector<std::int64_t> times_ns,
                                             std::vector<double> positions_mm) {
    hotgauge::core::Recording rec;
    rec.part_id = "P1";
    rec.recipe = "hub-a";
    rec.captured_at = "2026-12-02T06:00:00Z";
    hotgauge::core::FaceScan f;
    f.name = "top";
    f.width = 1;
    f.profiles_mm = std::move(profiles_mm);
    f.profile_times_ns = std::move(times_ns);
    f.profile_positions_mm = std::move(positions_mm);
    f.accel_mps2 = {0, 0, 9.81f, 0, 0, 9.81f};
    f.accel_times_ns = {999'000'000, 1'002'000'000};
    rec.faces.push_back(std::move(f));
    return rec;
}

// The error reading `text` with `from` replaced by `to` ("" when it reads).
std::string error_with(const std::string& from, const std::string& to) {
    hotgauge::test::TempDir tmp;
    const auto good = tmp.path / "good.yaml";
    EXPECT_TRUE(calib::write_calibration(example(), good).ok());
    std::string text = text_of(good);
    const auto at = text.find(from);
    EXPECT_NE(at, std::string::npos) << from;
    if (at != std::string::npos) text.replace(at, from.size(), to);
    const auto bad = tmp.path / "bad.yaml";
    std::ofstream(bad) << text;
    auto c = calib::read_calibration(bad);
    return c.ok() ? "" : c.error().message;
}

}  // namespace

TEST(Calibration, ReadsBackWhatWasWritten) {
    hotgauge::test::TempDir tmp;
    const calib::Calibration c = example();
    ASSERT_TRUE(calib::write_calibration(c, tmp.path / "calibration.yaml").ok());
    auto r = calib::read_calibration(tmp.path / "calibration.yaml");
    ASSERT_TRUE(r.ok()) << r.error().message;
    EXPECT_EQ(r->calibrated_at, c.calibrated_at);
    EXPECT_EQ(r->method, c.method);
    EXPECT_EQ(r->source, c.source);
    EXPECT_EQ(r->residuals, c.residuals);
    EXPECT_EQ(r->sensor.baseline_mm, c.sensor.baseline_mm);
    EXPECT_EQ(r->clock_offset_ns, c.clock_offset_ns);
    EXPECT_EQ(r->accel_bias_mps2, c.accel_bias_mps2);
    ASSERT_EQ(r->faces.size(), 2u);
    for (std::size_t i = 0; i < 2; ++i) {
        EXPECT_EQ(r->faces[i].name, c.faces[i].name);
        EXPECT_EQ(r->faces[i].T_world_camera.matrix(), c.faces[i].T_world_camera.matrix());
        EXPECT_EQ(r->faces[i].scan_direction, c.faces[i].scan_direction);
        EXPECT_EQ(r->faces[i].travel_scale, c.faces[i].travel_scale);
        EXPECT_EQ(r->faces[i].R_camera_accel, c.faces[i].R_camera_accel);
    }
    EXPECT_TRUE(r->measured());
    EXPECT_NE(r->face("side1"), nullptr);
    EXPECT_EQ(r->face("bottom"), nullptr);
}

TEST(Calibration, BadFieldsAreRefusedByName) {
    EXPECT_EQ(error_with("method:", "method:"), "");
    const struct {
        std::string from, to, expect;
    } cases[] = {
        {"format: hotgauge-calibration-1", "format: hotgauge-calibration-9", "format:"},
        {"clock_offset_ns:", "clock_offset_ms:", "clock_offset_ms"},
        {"model: direct_beam", "model: fisheye", "sensor.model: 'fisheye' is not known"},
        {"min_range_mm: 600", "min_range_mm: 1300", "min_range_mm must be below"},
        {"travel_scale: ", "travel_scale: -", "faces[0].travel_scale: must be positive"},
        {"scan_direction: [0.000", "scan_direction: [2.000",
         "faces[0].scan_direction: must be a unit"},
        {"- name: \"side1\"", "- name: \"top\"", "faces[1].name: duplicate face 'top'"},
        {"accel_to_camera: [[", "accel_to_camera: [[-", "faces[0].accel_to_camera"},
        {"baseline_mm: 301.25", "baseline_mm: x", "sensor.baseline_mm"},
    };
    for (const auto& k : cases) {
        const std::string e = error_with(k.from, k.to);
        EXPECT_NE(e.find("bad.yaml:"), std::string::npos) << k.from << " → " << e;
        EXPECT_NE(e.find(k.expect), std::string::npos) << k.from << " → " << e;
    }
    auto missing = calib::read_calibration("/nonexistent/calibration.yaml");
    ASSERT_FALSE(missing.ok());
    EXPECT_NE(missing.error().message.find("/nonexistent/calibration.yaml"), std::string::npos);
}

// The shipped calibration is what `hotgauge calibrate nominal` makes of config/cell.yaml: if one
// of the two files changes alone, the daemon would scan with other poses than the virtual cell
// renders.
TEST(Calibration, ShippedNominalMatchesTheCellConfig) {
    auto cell = sim::read_cell_config(kConfig + "/cell.yaml");
    ASSERT_TRUE(cell.ok()) << cell.error().message;
    auto shipped = calib::read_calibration(kConfig + "/calibration.yaml");
    ASSERT_TRUE(shipped.ok()) << shipped.error().message;
    EXPECT_FALSE(shipped->measured());
    const auto nominal = sim::nominal_calibration(*cell, "config/cell.yaml", "now");
    ASSERT_EQ(shipped->faces.size(), nominal.faces.size());
    for (std::size_t i = 0; i < nominal.faces.size(); ++i) {
        const auto& a = shipped->faces[i];
        const auto& b = nominal.faces[i];
        EXPECT_EQ(a.name, b.name);
        EXPECT_TRUE(a.T_world_camera.matrix().isApprox(b.T_world_camera.matrix(), 1e-12)) << a.name;
        EXPECT_TRUE(a.scan_direction.isApprox(b.scan_direction, 1e-12)) << a.name;
        EXPECT_TRUE(a.R_camera_accel.isApprox(b.R_camera_accel, 1e-12)) << a.name;
        EXPECT_EQ(a.travel_scale, 1.0);
    }
    EXPECT_EQ(shipped->sensor.width, nominal.sensor.width);
    EXPECT_EQ(shipped->sensor.baseline_mm, nominal.sensor.baseline_mm);
    EXPECT_EQ(shipped->sensor.standoff_mm, nominal.sensor.standoff_mm);
}

// The daemon's triangulation (from the calibration) and the virtual camera's (from the cell
// config) map every pixel to the same point.
TEST(Calibration, TriangulationMatchesTheSimulatorsSensor) {
    auto cell = sim::read_cell_config(kConfig + "/cell.yaml");
    ASSERT_TRUE(cell.ok());
    const auto nominal = sim::nominal_calibration(*cell, "cell.yaml", "now");
    auto a = calib::triangulation(nominal.sensor);
    auto b = vcell::sensor_triangulation(cell->sensor);
    ASSERT_TRUE(a.ok() && b.ok());
    for (double u : {0.0, 700.5, 2047.0})
        for (double v : {10.25, 544.0, 1000.75}) {
            const auto pa = a->to_camera(u, v);
            const auto pb = b->to_camera(u, v);
            EXPECT_EQ(pa.x_mm, pb.x_mm);
            EXPECT_EQ(pa.z_mm, pb.z_mm);
        }
    calib::SensorModel bad = nominal.sensor;
    bad.baseline_mm = 0.0;
    EXPECT_FALSE(calib::triangulation(bad).ok());
}

// An image-mode sensor calibration (model pinhole) reads back to the same numbers and becomes the
// calibrated triangulation: a pixel lands where its ray meets the laser plane (calib::triangulate)
// in the laser frame; a camera of another height than the one delivering frames is refused.
TEST(Calibration, PinholeSensorReadsBackAndTriangulates) {
    hotgauge::test::TempDir tmp;
    calib::Calibration c = example();
    c.method = "sensor";
    c.sensor.model = "pinhole";
    calib::PinholeCamera& k = c.sensor.camera;
    k.fx = 4318.25;
    k.fy = 4319.5;
    k.cx = 1027.125;
    k.cy = 540.5;
    k.distortion = {-0.06, 0.03, 2e-4, -1e-4, 0.0};
    c.sensor.width = k.width;
    c.sensor.plane.normal = Eigen::Vector3d(0, -0.9486832980505138, 0.31622776601683794);
    c.sensor.plane.offset_mm = 300.0;
    ASSERT_TRUE(calib::write_calibration(c, tmp.path / "c.yaml").ok());
    auto r = calib::read_calibration(tmp.path / "c.yaml");
    ASSERT_TRUE(r.ok()) << r.error().message;
    EXPECT_FALSE(r->measured());  // the faces are to be aligned again
    EXPECT_EQ(r->sensor.model, "pinhole");
    EXPECT_EQ(r->sensor.camera.fx, k.fx);
    EXPECT_EQ(r->sensor.camera.cy, k.cy);
    EXPECT_EQ(r->sensor.camera.distortion, k.distortion);
    EXPECT_EQ(r->sensor.plane.normal, c.sensor.plane.normal);
    EXPECT_EQ(r->sensor.plane.offset_mm, 300.0);
    auto tri = calib::triangulation(r->sensor);
    ASSERT_TRUE(tri.ok()) << tri.error().message;
    calib::SensorCalibration s;
    s.camera = k;
    s.plane = c.sensor.plane;
    const Eigen::Isometry3d T_laser_camera = calib::laser_frame(s);
    for (double u : {100.0, 1024.5, 1900.0})
        for (double v : {80.0, 544.0, 1000.0}) {
            const Eigen::Vector3d want = T_laser_camera * calib::triangulate(k, s.plane, u, v);
            const auto p = tri->to_camera(u, v);
            EXPECT_NEAR(p.x_mm, want.x(), 2e-3) << u << ", " << v;
            EXPECT_NEAR(p.z_mm, want.z(), 2e-3) << u << ", " << v;
        }
    auto other = calib::triangulation(r->sensor, 1024);
    ASSERT_FALSE(other.ok());
    EXPECT_EQ(other.error().message,
              "sensor: the calibration's camera has 1088 rows, the camera 1024");
    // A pinhole block with a direct-beam key is refused by name.
    std::string text = text_of(tmp.path / "c.yaml");
    text.replace(text.find("height:"), 7, "pitch_mm:");
    std::ofstream(tmp.path / "bad.yaml") << text;
    auto bad = calib::read_calibration(tmp.path / "bad.yaml");
    ASSERT_FALSE(bad.ok());
    EXPECT_NE(bad.error().message.find("pitch_mm"), std::string::npos) << bad.error().message;
}

// A recording takes the calibration's geometry face by face; a face the calibration lacks is an
// error naming it, and the recording is left as it was.
TEST(Calibration, ApplyGeometryReplacesFaceYamlAndScalesTheTravel) {
    const calib::Calibration c = example();
    hotgauge::core::Recording rec;
    hotgauge::core::FaceScan f;
    f.name = "side1";
    f.profile_positions_mm = {0.0, 0.2, 100.0};
    rec.faces.push_back(f);
    ASSERT_TRUE(calib::apply_geometry(c, "cal.yaml", rec).ok());
    const auto& g = *c.face("side1");
    EXPECT_EQ(rec.faces[0].T_world_camera.matrix(), g.T_world_camera.matrix());
    EXPECT_EQ(rec.faces[0].scan_direction, g.scan_direction);
    EXPECT_EQ(rec.faces[0].R_camera_accel, g.R_camera_accel);
    EXPECT_DOUBLE_EQ(rec.faces[0].profile_positions_mm[2], 100.0 * g.travel_scale);

    f.name = "bottom";
    rec.faces.push_back(f);
    const auto before = rec.faces[0].profile_positions_mm;
    auto e = calib::apply_geometry(c, "cal.yaml", rec);
    ASSERT_FALSE(e.ok());
    EXPECT_EQ(e.error().message, "cal.yaml: no face 'bottom' (the recording has it)");
    EXPECT_EQ(rec.faces[0].profile_positions_mm, before);
    EXPECT_TRUE(rec.faces[1].T_world_camera.matrix().isIdentity());
}

// What the capture already applied (face.yaml's travel_scale and clock_offset_ns) is replaced,
// not applied twice: measured again with the calibration it was recorded with, a recording is
// unchanged; with another, positions and times move by the difference. The keys survive the
// recording writer and reader.
TEST(Calibration, ApplyGeometryReplacesWhatTheCaptureApplied) {
    const calib::Calibration c = example();
    const auto& g = *c.face("top");
    hotgauge::core::Recording rec =
        top_face_recording({1.0f, 900.0f, 2.0f, 901.0f}, {1'000'000'000, 1'001'000'000},
                           {0.0, 100.0 * g.travel_scale});
    hotgauge::core::FaceScan& f = rec.faces[0];
    f.travel_scale = g.travel_scale;
    f.clock_offset_ns = c.clock_offset_ns;
    hotgauge::test::TempDir dir;
    ASSERT_TRUE(hotgauge::io::write_recording(rec, dir.path / "rec").ok());
    auto back = hotgauge::io::read_recording(dir.path / "rec");
    ASSERT_TRUE(back.ok()) << back.error().message;
    EXPECT_EQ(back->faces[0].travel_scale, g.travel_scale);
    EXPECT_EQ(back->faces[0].clock_offset_ns, c.clock_offset_ns);

    hotgauge::core::Recording same = *back;
    ASSERT_TRUE(calib::apply_geometry(c, "cal.yaml", same).ok());
    EXPECT_DOUBLE_EQ(same.faces[0].profile_positions_mm[1], 100.0 * g.travel_scale);
    EXPECT_EQ(same.faces[0].profile_times_ns, f.profile_times_ns);

    calib::Calibration other = c;
    for (auto& face : other.faces) face.travel_scale = 1.0;
    other.clock_offset_ns = 0;
    ASSERT_TRUE(calib::apply_geometry(other, "other.yaml", same).ok());
    EXPECT_DOUBLE_EQ(same.faces[0].profile_positions_mm[1], 100.0);
    EXPECT_EQ(same.faces[0].profile_times_ns[0], 1'000'000'000 - c.clock_offset_ns);
    EXPECT_EQ(same.faces[0].accel_times_ns, f.accel_times_ns);
    EXPECT_EQ(same.faces[0].travel_scale, 1.0);
    EXPECT_EQ(same.faces[0].clock_offset_ns, 0);
}

// `calibrate faces` keeps the pose the artifact recording claimed. Another tool's recording that
// claims that pose takes the calibrated one; one that places the head elsewhere (another cell's
// stand-off or start set per part) keeps its placement and takes the calibrated correction of
// the mount; a recording this software wrote (`geometry_source: calibration`, a fixed head) takes
// the calibrated pose whatever it says. The keys survive write and read.
TEST(Calibration, ApplyGeometryCorrectsAHeadPlacedElsewhere) {
    calib::Calibration c = example();
    calib::FaceCalibration& g = c.faces[0];
    Eigen::Isometry3d claimed = g.T_world_camera;
    claimed.translation() += Eigen::Vector3d(0.7, -0.4, 1.5);
    claimed.linear() =
        Eigen::AngleAxisd(0.004, Eigen::Vector3d::UnitX()).toRotationMatrix() * claimed.linear();
    g.recorded_camera_to_world = claimed;
    hotgauge::test::TempDir tmp;
    ASSERT_TRUE(calib::write_calibration(c, tmp.path / "c.yaml").ok());
    auto back = calib::read_calibration(tmp.path / "c.yaml");
    ASSERT_TRUE(back.ok()) << back.error().message;
    ASSERT_TRUE(back->faces[0].recorded_camera_to_world);
    EXPECT_TRUE(
        back->faces[0].recorded_camera_to_world->matrix().isApprox(claimed.matrix(), 1e-15));
    EXPECT_FALSE(back->faces[1].recorded_camera_to_world);

    auto applied = [&](const Eigen::Isometry3d& face_yaml, bool ours) {
        hotgauge::core::Recording rec;
        hotgauge::core::FaceScan f;
        f.name = g.name;
        f.T_world_camera = face_yaml;
        f.geometry_from_calibration = ours;
        rec.faces.push_back(f);
        f.name = c.faces[1].name;
        rec.faces.push_back(f);
        EXPECT_TRUE(calib::apply_geometry(*back, "c.yaml", rec).ok());
        return rec.faces[0].T_world_camera;
    };
    EXPECT_TRUE(applied(claimed, false).isApprox(g.T_world_camera, 1e-12));
    // The head 58.8 mm further along the scan and 1.1 mm nearer: so is the calibrated camera.
    Eigen::Isometry3d moved = claimed;
    moved.pretranslate(Eigen::Vector3d(1.1, 58.8, 0.0));
    Eigen::Isometry3d want = g.T_world_camera;
    want.pretranslate(Eigen::Vector3d(1.1, 58.8, 0.0));
    EXPECT_TRUE(applied(moved, false).isApprox(want, 1e-12));
    // Written by this software with an older calibration in force: the new one replaces it.
    EXPECT_TRUE(applied(moved, true).isApprox(g.T_world_camera, 1e-12));

    hotgauge::core::Recording rec = top_face_recording({1.0f, 900.0f}, {1'000'000'000}, {0.0});
    rec.faces[0].geometry_from_calibration = true;
    ASSERT_TRUE(hotgauge::io::write_recording(rec, tmp.path / "rec").ok());
    auto read = hotgauge::io::read_recording(tmp.path / "rec");
    ASSERT_TRUE(read.ok()) << read.error().message;
    EXPECT_TRUE(read->faces[0].geometry_from_calibration);
}
