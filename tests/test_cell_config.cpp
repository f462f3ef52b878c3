// The daemon's configuration (config/hotgauged.yaml): the example reads, and every kind of
// mistake is an error naming file:line and the key.
#include <gtest/gtest.h>

#include <algorithm>
#include <cctype>
#include <fstream>
#include <sstream>

#include "../src/cell/device_watch.hpp"
#include "../src/cell/plc_result.hpp"
#include "hotgauge/cell/config.hpp"
#include "hotgauge/cell/journal.hpp"
#include "hotgauge/compensate/compensate.hpp"
#include "hotgauge/core/clock.hpp"
#include "temp_dir.hpp"

namespace hotgauge {
namespace {

const std::string kConfigDir = HOTGAUGE_SOURCE_DIR "/config";

TEST(DaemonConfig, TheExampleReads) {
    auto c = cell::read_daemon_config(kConfigDir + "/hotgauged.yaml");
    ASSERT_TRUE(c.ok()) << c.error().message;
    EXPECT_EQ(c->acquisition.camera.id, "127.0.0.2");
    EXPECT_EQ(c->acquisition.scan.frame_mode, "peaks");
    EXPECT_EQ(c->acquisition.scan.peaks.profiles_per_frame, 10);
    EXPECT_NEAR(c->acquisition.scan.line_period_s, 1e-3, 1e-12);
    EXPECT_EQ(c->acquisition.exposure_table.size(), 4u);
    EXPECT_EQ(c->faces, (std::vector<std::string>{"top", "bottom", "side1", "side2"}));
    ASSERT_EQ(c->recipes.count(1), 1u);
    EXPECT_TRUE(std::filesystem::exists(c->recipes.at(1)));
    ASSERT_TRUE(c->accelerometer);
    EXPECT_EQ(c->accelerometer->udp.bind, "127.0.0.1:47355");
    EXPECT_EQ(c->axis.kind, "modbus");
    EXPECT_EQ(c->axis.faces.at("side2"), 4);
    EXPECT_EQ(c->plc.port, 502);
    ASSERT_TRUE(c->pyrometer);
    EXPECT_EQ(c->pyrometer->serial.device, "/tmp/pyro");
    EXPECT_NEAR(c->acquisition.scan_s, 1.3, 1e-12);
    EXPECT_NEAR(c->accel_margin_s, 0.5, 1e-12);
    EXPECT_EQ(c->archive.every_nth_ok, 50);
    EXPECT_TRUE(c->status_page.enabled);
    EXPECT_EQ(c->status_page.bind_address, "127.0.0.1");
    EXPECT_EQ(c->status_page.port, 8080);
    EXPECT_TRUE(c->metrics.enabled);
    EXPECT_EQ(c->metrics.bind_address, "127.0.0.1");
    EXPECT_EQ(c->metrics.port, 9464);
    EXPECT_FALSE(c->mqtt);  // commented out: no broker in the example
    EXPECT_EQ(c->hash.size(), 16u);
    EXPECT_TRUE(std::all_of(c->hash.begin(), c->hash.end(),
                            [](char ch) { return std::isxdigit(static_cast<unsigned char>(ch)); }));
}

// The example with one line replaced (or appended); the result's error, or "" when it read.
std::string error_with(const std::string& from, const std::string& to, int* line = nullptr) {
    std::ifstream in(kConfigDir + "/hotgauged.yaml");
    std::stringstream ss;
    ss << in.rdbuf();
    std::string text = ss.str();
    // Paths relative to the example's folder become absolute, as the copy lives elsewhere.
    const auto swap = [&](const std::string& a, const std::string& b) {
        const auto at = text.find(a);
        ASSERT_NE(at, std::string::npos) << a;
        text.replace(at, a.size(), b);
    };
    swap("calibration: calibration.yaml", "calibration: " + kConfigDir + "/calibration.yaml");
    swap("1: parts/hub-a.yaml", "1: " + kConfigDir + "/parts/hub-a.yaml");
    if (from.empty()) {
        text += to + "\n";
    } else {
        const auto at = text.find(from);
        EXPECT_NE(at, std::string::npos) << from;
        if (line) *line = static_cast<int>(std::count(text.begin(), text.begin() + at, '\n')) + 1;
        text.replace(at, from.size(), to);
    }
    test::TempDir tmp;
    const auto file = tmp.path / "hotgauged.yaml";
    std::ofstream(file) << text;
    auto c = cell::read_daemon_config(file);
    if (c.ok()) return "";
    // Every message starts with the file and a line number.
    EXPECT_EQ(c.error().message.rfind(file.string() + ":", 0), 0u) << c.error().message;
    return c.error().message;
}

TEST(DaemonConfig, MistakesAreNamedWithFileLineAndKey) {
    EXPECT_EQ(error_with("", ""), "");  // the copy itself reads
    int line = 0;
    auto e = error_with("  mode: peaks", "  mode: laser", &line);
    EXPECT_NE(e.find(":" + std::to_string(line) + ": camera.mode: must be image or peaks"),
              std::string::npos)
        << e;
    e = error_with("  port: 502", "  port: 70000", &line);
    EXPECT_NE(e.find(":" + std::to_string(line) + ": plc.port: must be in 0..65535"),
              std::string::npos)
        << e;
    e = error_with("faces: {top: 1, bottom: 2, side1: 3, side2: 4}", "faces: {top: 1, bottom: 2}");
    EXPECT_NE(e.find("axis.faces: no position for face 'side1'"), std::string::npos) << e;
    e = error_with("[1000, 100], [1200, 50]", "[1000, 100], [900, 50]");
    EXPECT_NE(e.find("camera.exposure_table: exposure table point 4: temperatures must increase"),
              std::string::npos)
        << e;
    e = error_with("", "colour: red");  // a typo must not pass silently
    EXPECT_NE(e.find("colour"), std::string::npos) << e;
    e = error_with("1: " + kConfigDir + "/parts/hub-a.yaml", "1: /nonexistent/hub-z.yaml");
    EXPECT_NE(e.find("recipes: /nonexistent/hub-z.yaml does not exist"), std::string::npos) << e;
    e = error_with("  source: udp", "  source: carrier-pigeon");
    EXPECT_NE(e.find("accelerometer.source"), std::string::npos) << e;
    e = error_with("  id: 127.0.0.2", "  name: 127.0.0.2");
    EXPECT_NE(e.find("camera"), std::string::npos) << e;
    // Master slots (docs/verification.md): a certificate for a slot that has a recipe.
    EXPECT_EQ(error_with("", "masters: {1: " + kConfigDir + "/calibration.yaml}"), "");
    e = error_with("", "masters: {9: " + kConfigDir + "/calibration.yaml}");
    EXPECT_NE(e.find("masters: slot 9 has no recipe"), std::string::npos) << e;
    e = error_with("", "masters: {1: /nonexistent/master.yaml}");
    EXPECT_NE(e.find("masters: /nonexistent/master.yaml does not exist"), std::string::npos) << e;
}

// The geometry moved from the simulator's cell config to the calibration, the clock offset
// with it: a config written for the old keys says where they went.
TEST(DaemonConfig, StatusPageIsOnlyWhatTheConfigAsksFor) {
    int line = 0;
    auto e = error_with("  port: 8080", "  port: 80800", &line);
    EXPECT_NE(e.find(":" + std::to_string(line) + ": status_page.port: must be in 0..65535"),
              std::string::npos)
        << e;
    e = error_with("  port: 8080", "  port: 8080\n  allow_writes: true", &line);
    EXPECT_NE(e.find("status_page"), std::string::npos) << e;
    EXPECT_NE(e.find("allow_writes"), std::string::npos) << e;
    e = error_with("  bind_address: 127.0.0.1        #", "  bind_address: ''        #", &line);
    EXPECT_NE(e.find(":" + std::to_string(line) +
                     ": status_page.bind_address: expected a non-empty string"),
              std::string::npos)
        << e;
    // Without the section: no page, no port.
    test::TempDir tmp;
    std::ifstream in(kConfigDir + "/hotgauged.yaml");
    std::stringstream ss;
    ss << in.rdbuf();
    std::string text = ss.str();
    const auto from = text.find("status_page:"), to = text.find("plc:", from);
    ASSERT_NE(from, std::string::npos);
    text.erase(from, to - from);
    std::ofstream(tmp.path / "hotgauged.yaml") << text;
    std::filesystem::copy(kConfigDir + "/calibration.yaml", tmp.path / "calibration.yaml");
    std::filesystem::create_directories(tmp.path / "parts");
    std::filesystem::copy(kConfigDir + "/parts/hub-a.yaml", tmp.path / "parts/hub-a.yaml");
    auto c = cell::read_daemon_config(tmp.path / "hotgauged.yaml");
    ASSERT_TRUE(c.ok()) << c.error().message;
    EXPECT_FALSE(c->status_page.enabled);
}

TEST(DaemonConfig, PipelineSettingsAsTheToolTakesThem) {
    auto c = cell::read_daemon_config(kConfigDir + "/hotgauged.yaml");
    ASSERT_TRUE(c.ok()) << c.error().message;
    EXPECT_TRUE(c->pipeline.compensate);
    EXPECT_EQ(c->pipeline.highpass_hz, compensate::CompensationConfig{}.highpass_hz);
    EXPECT_EQ(c->pipeline.threads, 0);
    int line = 0;
    auto e = error_with("  highpass_hz: 1.5 ", "  highpass_hz: -2  ", &line);
    EXPECT_NE(e.find(":" + std::to_string(line) + ": pipeline.highpass_hz: must be positive"),
              std::string::npos)
        << e;
    e = error_with("  highpass_hz: 1.5 ", "  highpass_hz: 80  ", &line);
    EXPECT_NE(e.find(":" + std::to_string(line) + ": pipeline.highpass_hz: at most 50 Hz"),
              std::string::npos)
        << e;
    e = error_with("  threads: 0 ", "  threads: -1 ", &line);
    EXPECT_NE(e.find(":" + std::to_string(line) + ": pipeline.threads: must be in 0..64"),
              std::string::npos)
        << e;
    e = error_with("  compensation: true ", "  compensation: maybe ", &line);
    EXPECT_NE(e.find(":" + std::to_string(line) + ": pipeline.compensation"), std::string::npos)
        << e;
    e = error_with("  threads: 0 ", "  threads: 0\n  icp_stop_deg: 1 ", &line);
    EXPECT_NE(e.find("icp_stop_deg"), std::string::npos) << e;  // no setting that nothing reads
}

TEST(DaemonConfig, MqttSettingsAreCheckedBeforeTheBrokerIsTried) {
    const std::string ca = kConfigDir + "/calibration.yaml";  // any file that exists
    const std::string good = "mqtt:\n  host: 127.0.0.1\n  site: plant-1\n  cell: line-3\n";
    EXPECT_EQ(error_with("", good), "");
    EXPECT_EQ(
        error_with("", good + "  username: u\n  password_file: " + ca + "\n  tls: {ca_file: " + ca +
                           ", cert_file: " + ca + ", key_file: " + ca + "}\n  spool_max_mb: 16"),
        "");
    auto e = error_with("", "mqtt:\n  host: 127.0.0.1\n  site: plant/1\n  cell: line-3");
    EXPECT_NE(e.find("mqtt.site: a topic level: not empty, without '/', '+' or '#'"),
              std::string::npos)
        << e;
    e = error_with("", "mqtt:\n  host: 127.0.0.1\n  site: plant-1");
    EXPECT_NE(e.find("cell"), std::string::npos) << e;
    e = error_with("", good + "  username: u\n  password_file: /nonexistent/pw");
    EXPECT_NE(e.find("mqtt.password_file: /nonexistent/pw does not exist"), std::string::npos) << e;
    e = error_with("", good + "  password_file: " + ca);
    EXPECT_NE(e.find("mqtt.password_file: needs a username"), std::string::npos) << e;
    e = error_with("", good + "  tls: {ca_file: " + ca + ", cert_file: " + ca + "}");
    EXPECT_NE(e.find("mqtt.tls: a client certificate needs both cert_file and key_file"),
              std::string::npos)
        << e;
    e = error_with("", good + "  password: in-the-config");  // not a key: the password_file is
    EXPECT_NE(e.find("password"), std::string::npos) << e;
    e = error_with("", good + "  retry_min_s: 10\n  retry_max_s: 5");
    EXPECT_NE(e.find("mqtt.retry_max_s: less than retry_min_s"), std::string::npos) << e;
}

TEST(DaemonConfig, GeometryKeysThatMovedToTheCalibrationSaySo) {
    auto e = error_with("calibration: " + kConfigDir + "/calibration.yaml",
                        "cell: " + kConfigDir + "/cell.yaml");
    EXPECT_NE(e.find("cell: the daemon takes the cell's geometry from its calibration"),
              std::string::npos)
        << e;
    e = error_with("  line_rate_hz: 1000", "  line_rate_hz: 1000\n  clock_offset_ns: 1500");
    EXPECT_NE(e.find("camera.clock_offset_ns: the camera → accelerometer clock offset is measured "
                     "now: clock_offset_ns in the calibration file"),
              std::string::npos)
        << e;
    e = error_with("calibration: " + kConfigDir + "/calibration.yaml",
                   "calibration: /nonexistent/calibration.yaml");
    EXPECT_NE(e.find("calibration: /nonexistent/calibration.yaml does not exist"),
              std::string::npos)
        << e;
}

// Issue 18, finding 2: paths the filesystem cannot even look at made std::filesystem::exists
// throw through the reader (exit 134, a daemon killed by SIGHUP). They are errors now, naming
// the file, the line and the reason.
TEST(DaemonConfig, PathsTheFilesystemRefusesAreErrorsNotExceptions) {
    test::TempDir dir;
    const auto loop = dir.path / "loop";
    std::filesystem::create_symlink(loop, loop);  // a symlink to itself: ELOOP on stat
    const std::string too_long(300, 'x');         // over NAME_MAX: ENAMETOOLONG
    const std::string recipe = "1: " + kConfigDir + "/parts/hub-a.yaml";
    int line = 0;
    for (const std::string& bad : {loop.string() + "/hub-a.yaml", "/tmp/" + too_long}) {
        std::string e;
        EXPECT_NO_THROW(e = error_with(recipe, "1: " + bad, &line)) << bad;
        EXPECT_NE(e.find(":" + std::to_string(line) + ": recipes: " + bad), std::string::npos) << e;
        EXPECT_EQ(e.find("does not exist"), std::string::npos) << "the reason, not a guess: " << e;
    }
    for (const std::filesystem::path& file :
         {loop / "hotgauged.yaml", std::filesystem::path("/tmp") / too_long}) {
        EXPECT_NO_THROW({
            auto r = cell::read_daemon_config(file);
            ASSERT_FALSE(r.ok());
            EXPECT_NE(r.error().message.find(file.string()), std::string::npos);
        });
    }
}

TEST(DaemonConfig, AMissingFileIsNamed) {
    auto c = cell::read_daemon_config("/nonexistent/hotgauged.yaml");
    ASSERT_FALSE(c.ok());
    EXPECT_NE(c.error().message.find("/nonexistent/hotgauged.yaml"), std::string::npos);
}

}  // namespace

// ---- device health, calibration state, reason bits (docs/plc-modbus.md, map version 4) ----

namespace {
constexpr std::int64_t kS = 1'000'000'000;
}

TEST(DeviceWatch, AQuestionWithoutAnAnswerIsAFaultBeforeTheTransportGivesUp) {
    cell::DeviceWatch w;
    EXPECT_FALSE(w.status(cell::Device::kAxis, false, 0).configured);
    EXPECT_FALSE(w.status(cell::Device::kCamera, true, 0).ok);  // never asked: not known well
    w.answered(cell::Device::kCamera, true, "answering");
    EXPECT_TRUE(w.status(cell::Device::kCamera, true, 1 * kS).ok);
    w.probe_started(cell::Device::kCamera, 2 * kS);
    // Pending, but not yet for longer than a healthy device takes: the last answer stands.
    EXPECT_TRUE(w.status(cell::Device::kCamera, true, 2 * kS + cell::DeviceWatch::kNoAnswerNs).ok);
    const auto late = w.status(cell::Device::kCamera, true, 3 * kS);
    EXPECT_FALSE(late.ok);
    EXPECT_EQ(late.detail, "no answer for 1000 ms");
    w.answered(cell::Device::kCamera, false, "lost");
    EXPECT_EQ(w.status(cell::Device::kCamera, true, 4 * kS).detail, "lost");
    cell::DeviceHealth h;
    h[cell::Device::kCamera] = w.status(cell::Device::kCamera, true, 4 * kS);
    h[cell::Device::kResultsDisk] = {true, false, "full"};
    h[cell::Device::kPyrometer] = {false, false, "not configured"};  // never a fault
    EXPECT_EQ(h.fault_bits(), 0b10001);
}

TEST(DeviceWatch, TheResultsDiskNeedsItsFolderWritableAndFreeSpace) {
    test::TempDir dir;
    EXPECT_TRUE(cell::disk_status(dir.path, 1, "").ok);
    EXPECT_FALSE(cell::disk_status(dir.path / "gone", 1, "").ok);
    const auto full = cell::disk_status(dir.path, 1'000'000'000, "");  // a petabyte
    EXPECT_FALSE(full.ok);
    EXPECT_NE(full.detail.find("below 1000000000 MB"), std::string::npos) << full.detail;
    const auto failed = cell::disk_status(dir.path, 1, "No space left on device");
    EXPECT_FALSE(failed.ok);
    EXPECT_NE(failed.detail.find("No space left"), std::string::npos);
}

TEST(CalibrationStatus, ValidDueNotMeasuredAndUnknown) {
    const auto at = core::parse_iso8601_utc("2026-06-01T12:00:00Z");
    ASSERT_TRUE(at);
    EXPECT_EQ(core::iso8601_utc(*at), "2026-06-01T12:00:00Z");  // the writer's reverse
    EXPECT_FALSE(core::parse_iso8601_utc("2026-13-01T00:00:00Z"));
    EXPECT_FALSE(core::parse_iso8601_utc("yesterday"));
    const std::int64_t day = 86'400 * kS;
    auto s = cell::calibration_status("2026-06-01T12:00:00Z", true, 180, *at + 10 * day + 5);
    EXPECT_EQ(s.calibration, plc::CalibrationState::kValid);
    EXPECT_EQ(s.calibration_age_days, 10);
    s = cell::calibration_status("2026-06-01T12:00:00Z", true, 180, *at + 181 * day);
    EXPECT_EQ(s.calibration, plc::CalibrationState::kDue);
    s = cell::calibration_status("2026-06-01T12:00:00Z", false, 180, *at + day);
    EXPECT_EQ(s.calibration, plc::CalibrationState::kNotMeasured);
    s = cell::calibration_status("", true, 180, *at);
    EXPECT_EQ(s.calibration, plc::CalibrationState::kUnknown);
    EXPECT_FALSE(s.calibration_age_days);
}

TEST(ReasonBits, FromWhatTheMeasurementRecorded) {
    measure::FeatureResult f;
    f.name = "Diameter 1";
    f.tol_lower_mm = -0.1;
    f.tol_upper_mm = 0.1;
    f.verdict = measure::Verdict::kOk;
    f.hot_mm = 139.0;
    f.cold_mm = 138.0;
    f.deviation_mm = 0.05;
    EXPECT_EQ(cell::feature_reasons(f, nullptr), 0);
    f.low_coverage = true;
    EXPECT_EQ(cell::feature_reasons(f, nullptr), plc::reason::kLowCoverage);
    f.low_coverage = false;
    f.deviation_mm = 0.2;  // degraded and outside: both said
    f.verdict = measure::Verdict::kDegraded;
    EXPECT_EQ(cell::feature_reasons(f, nullptr),
              plc::reason::kDegraded | plc::reason::kOutsideTolerance);
    f.cold_mm.reset();  // no temperature: a hot value only
    f.deviation_mm.reset();
    f.verdict = measure::Verdict::kNotMeasured;
    EXPECT_EQ(cell::feature_reasons(f, nullptr),
              plc::reason::kNotMeasured | plc::reason::kTemperatureUnknown);
    f.hot_mm.reset();
    f.face_missing = true;
    EXPECT_EQ(cell::feature_reasons(f, nullptr),
              plc::reason::kNotMeasured | plc::reason::kFaceMissing);
    pipeline::Verification check;
    check.features.push_back({});
    check.features.back().name = "Diameter 1";
    EXPECT_EQ(cell::feature_reasons(f, &check) & plc::reason::kMasterCheckFailed,
              plc::reason::kMasterCheckFailed);
    check.features.back().passed = true;
    EXPECT_EQ(cell::feature_reasons(f, &check) & plc::reason::kMasterCheckFailed, 0);
}

// The register map holds 16 feature blocks: a 17th feature, or a slot past 16, is refused naming
// the feature (the daemon's load_setup and `hotgauge plc map --recipe`).
TEST(RecipeForTheCell, SlotsWithinTheRegisterMapAndFacesTheCellScans) {
    core::Recipe r;
    r.name = "hub-x";
    for (int i = 1; i <= 16; ++i) {
        core::FeatureSpec f;
        f.name = "F" + std::to_string(i);
        f.slot = i;
        f.faces = {"top"};
        r.features.push_back(f);
    }
    const std::vector<std::string> top{"top"}, side{"side1"};
    EXPECT_TRUE(cell::check_recipe_for_cell(r, "r.yaml", &top).ok());
    EXPECT_TRUE(cell::check_recipe_for_cell(r, "r.yaml", nullptr).ok());
    auto unscanned = cell::check_recipe_for_cell(r, "r.yaml", &side);
    ASSERT_FALSE(unscanned.ok());
    EXPECT_NE(unscanned.error().message.find("r.yaml: recipe hub-x: feature 'F1' (slot 1) needs "
                                             "face 'top'"),
              std::string::npos)
        << unscanned.error().message;
    auto more = r;
    more.features.push_back(r.features[0]);
    more.features.back().name = "F17";
    more.features.back().slot = 17;
    auto seventeen = cell::check_recipe_for_cell(more, "r.yaml", &top);
    ASSERT_FALSE(seventeen.ok());
    EXPECT_NE(seventeen.error().message.find(
                  "17 features (the 17th: 'F17'); the PLC's register map holds 16"),
              std::string::npos)
        << seventeen.error().message;
    auto high = r;
    high.features[15].slot = 40;
    const auto past = cell::check_recipe_for_cell(high, "r.yaml", &top);
    ASSERT_FALSE(past.ok());
    EXPECT_NE(past.error().message.find("feature 'F16': slot 40 is outside 1..16"),
              std::string::npos);
    auto twice = r;
    twice.features[15].slot = 3;
    const auto shared = cell::check_recipe_for_cell(twice, "r.yaml", nullptr);
    ASSERT_FALSE(shared.ok());
    EXPECT_NE(shared.error().message.find("features 'F3' and 'F16' are both on slot 3"),
              std::string::npos);
    // A forging's diameter needs only its first face: the others give its wall, for the draft.
    auto forged = r;
    forged.forging.emplace();
    forged.features[0].faces = {"top", "side1"};
    EXPECT_TRUE(cell::check_recipe_for_cell(forged, "r.yaml", &top).ok());
    forged.features[1].faces = {"top", "side1"};
    forged.features[1].kind = core::FeatureKind::kHeight;
    EXPECT_FALSE(cell::check_recipe_for_cell(forged, "r.yaml", &top).ok()) << "a height needs all";
}

// What the PLC was shown, kept in the results line, reads back the same (a part triggered again
// after a crash is shown it again: docs/results.md "One commit per part").
TEST(ShownToThePlc, KeptInTheResultsLineReadsBackTheSame) {
    plc::PartResult p;
    p.overall = plc::Verdict::kNok;
    p.temperature_c = 1012.5;
    p.reasons = plc::reason::kDegraded;
    p.recipe_revision = 3;
    p.features = {{"Diameter 1", 1, 138.0123, plc::Verdict::kNok, true, plc::DriftState::kUp,
                   plc::reason::kOutsideTolerance},
                  {"Height 2", 4, std::nullopt, plc::Verdict::kNotMeasured, false,
                   plc::DriftState::kNone, plc::reason::kNotMeasured}};
    const std::string line =
        R"({"sequence":42,"time_ns":1795000000000000000,"plc":)" + cell::plc_json(p, 0) + "}";
    const auto back = cell::plc_from_json(line);
    ASSERT_TRUE(back.ok()) << back.error().message;
    EXPECT_EQ(back->fault, 0);
    EXPECT_EQ(back->result.overall, p.overall);
    EXPECT_EQ(back->result.temperature_c, p.temperature_c);
    EXPECT_EQ(back->result.reasons, p.reasons);
    EXPECT_EQ(back->result.recipe_revision, 3);
    EXPECT_EQ(back->result.sequence, 42u);
    EXPECT_EQ(back->result.time_ns, 1795000000000000000);
    ASSERT_EQ(back->result.features.size(), 2u);
    for (std::size_t i = 0; i < 2; ++i) {
        const auto &a = p.features[i], &b = back->result.features[i];
        EXPECT_EQ(a.name, b.name);
        EXPECT_EQ(a.slot, b.slot);
        EXPECT_EQ(a.value_mm, b.value_mm);  // the same double, to the bit
        EXPECT_EQ(a.verdict, b.verdict);
        EXPECT_EQ(a.required, b.required);
        EXPECT_EQ(a.drift, b.drift);
        EXPECT_EQ(a.reasons, b.reasons);
    }
    EXPECT_EQ(
        cell::plc_from_json(R"({"sequence":42,"time_ns":1,"plc":)" + cell::plc_json(p, 203) + "}")
            ->fault,
        203);
    const auto old = cell::plc_from_json(R"({"sequence":42,"time_ns":1})");  // an older line
    ASSERT_FALSE(old.ok());
    EXPECT_NE(old.error().message.find("\"plc\""), std::string::npos) << old.error().message;
}

}  // namespace hotgauge

// The journal's VERDICT field is what docs/operations.md tells a QE to filter on
// (journalctl VERDICT=NOT_MEASURED); it was the first word of the log line ("not").
TEST(Journal, VerdictFieldIsTheDocumentedName) {
    using hotgauge::cell::verdict_field;
    using hotgauge::plc::Verdict;
    EXPECT_EQ(verdict_field(false, Verdict::kOk), "OK");
    EXPECT_EQ(verdict_field(false, Verdict::kNok), "NOK");
    EXPECT_EQ(verdict_field(false, Verdict::kNotMeasured), "NOT_MEASURED");
    EXPECT_EQ(verdict_field(false, Verdict::kDegraded), "DEGRADED");
    EXPECT_EQ(verdict_field(true, Verdict::kOk), "FAULT");
}
