#include "hotgauge/cell/config.hpp"

#include <algorithm>
#include <fstream>
#include <iterator>
#include <set>
#include <sstream>

#include "hotgauge/accel/udp.hpp"
#include "hotgauge/cell/plc_sections.hpp"
#include "hotgauge/io/checksum.hpp"
#include "hotgauge/io/yaml_reader.hpp"
#include "hotgauge/plc/register_map.hpp"

namespace hotgauge::cell {
namespace {

namespace fs = std::filesystem;
using io::YamlReader;

// FNV-1a over the file's bytes, as 16 hex digits: which configuration measured a part.
std::string text_hash(std::string_view bytes) {
    char out[17];
    std::snprintf(out, sizeof out, "%016llx",
                  static_cast<unsigned long long>(io::fnv1a64(
                      reinterpret_cast<const unsigned char*>(bytes.data()), bytes.size())));
    return out;
}

}  // namespace

core::Result<void> check_recipe_for_cell(const core::Recipe& recipe, const fs::path& file,
                                         const std::vector<std::string>* faces) {
    const std::string where = file.string() + ": recipe " + recipe.name + ": ";
    const std::string map = "the PLC's register map holds " + std::to_string(plc::kMaxFeatures) +
                            " feature blocks (docs/plc-modbus.md)";
    if (recipe.features.size() > static_cast<std::size_t>(plc::kMaxFeatures))
        return core::make_error(where + std::to_string(recipe.features.size()) +
                                " features (the 17th: '" + recipe.features[16].name + "'); " + map);
    std::map<int, std::string> slots;
    for (const auto& f : recipe.features) {
        if (f.slot < 1 || f.slot > plc::kMaxFeatures)
            return core::make_error(where + "feature '" + f.name + "': slot " +
                                    std::to_string(f.slot) + " is outside 1.." +
                                    std::to_string(plc::kMaxFeatures) + "; " + map);
        if (auto [it, fresh] = slots.emplace(f.slot, f.name); !fresh)
            return core::make_error(where + "features '" + it->second + "' and '" + f.name +
                                    "' are both on slot " + std::to_string(f.slot));
        if (!faces) continue;
        // The faces without which it is never measured (measure::measure_one).
        const bool forged_diameter = recipe.forging && f.kind == core::FeatureKind::kDiameter;
        for (std::size_t i = 0;
             i < (forged_diameter ? std::min<std::size_t>(1, f.faces.size()) : f.faces.size()); ++i)
            if (std::find(faces->begin(), faces->end(), f.faces[i]) == faces->end())
                return core::make_error(where + "feature '" + f.name + "' (slot " +
                                        std::to_string(f.slot) + ") needs face '" + f.faces[i] +
                                        "', which the cell does not scan (faces: in the daemon's "
                                        "config): every part would read it NOT_MEASURED");
    }
    return {};
}

std::uint16_t recipe_revision(const fs::path& recipe_file) {
    std::ifstream in(recipe_file, std::ios::binary);
    const std::string bytes{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
    const std::uint64_t h =
        io::fnv1a64(reinterpret_cast<const unsigned char*>(bytes.data()), bytes.size());
    return static_cast<std::uint16_t>(h ^ (h >> 16) ^ (h >> 32) ^ (h >> 48));
}

std::string files_hash(const std::vector<fs::path>& files, const std::string& extra) {
    std::string bytes;
    for (const auto& file : files) {
        std::ifstream in(file, std::ios::binary);
        bytes += file.filename().string() + '\0';
        bytes.append(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
        bytes += '\0';
    }
    bytes += extra;
    char out[17];
    std::snprintf(out, sizeof out, "%016llx",
                  static_cast<unsigned long long>(io::fnv1a64(
                      reinterpret_cast<const unsigned char*>(bytes.data()), bytes.size())));
    return out;
}

namespace {

double positive(const YamlReader& y, const YAML::Node& map, const std::string& what,
                const char* key, double fallback) {
    const double v = y.number_or(map, what, key, fallback);
    if (!(v > 0.0)) y.fail(map[key] ? map[key] : map, what + "." + key + ": must be positive");
    return v;
}

// A path relative to the config file's folder; it must exist.
fs::path existing(const YamlReader& y, const YAML::Node& node, const std::string& what,
                  const fs::path& base) {
    return y.existing(node, what, base / y.string(node, what));
}

// camera.features: an ordered list of [NAME, VALUE].
void read_camera_features(const YamlReader& y, const YAML::Node& f, const std::string& w,
                          acquire::CameraConfig& cam) {
    if (!f.IsSequence()) y.fail(f, w + ".features: expected a list of [NAME, VALUE]");
    for (std::size_t i = 0; i < f.size(); ++i) {
        const auto pair = y.strings(f[i], w + ".features");
        if (pair.size() != 2) y.fail(f[i], w + ".features: expected [NAME, VALUE]");
        cam.features.emplace_back(pair[0], pair[1]);
    }
}

// camera.peaks: the format of the sensor's peak frames (mode: peaks).
void read_peaks(const YamlReader& y, const YAML::Node& p, const std::string& w,
                acquire::ScanConfig& scan) {
    const std::string pw = w + ".peaks";
    y.expect_map(p, pw,
                 {"profiles_per_frame", "fractional_bits", "row_offset", "second_peak", "intensity",
                  "width", "intensity_max_value"});
    auto& f = scan.peaks;
    f.profiles_per_frame =
        integer_in(y, p, pw, "profiles_per_frame", 1, 65535, f.profiles_per_frame);
    f.fractional_bits = integer_in(y, p, pw, "fractional_bits", 0, 15, f.fractional_bits);
    scan.offset_y_px = integer_in(y, p, pw, "row_offset", 0, 65535, 0);
    if (p["second_peak"]) f.second_peak = y.boolean(p["second_peak"], pw + ".second_peak");
    if (p["intensity"]) f.intensity = y.boolean(p["intensity"], pw + ".intensity");
    if (p["width"]) f.peak_width = y.boolean(p["width"], pw + ".width");
    f.intensity_max_value =
        integer_in(y, p, pw, "intensity_max_value", 1, 65535, f.intensity_max_value);
    if (auto ok = acquire::check_peak_format(f); !ok) y.fail(p, pw + ": " + ok.error().message);
}

// camera.stripe: the stripe extraction's settings (mode: image).
void read_stripe(const YamlReader& y, const YAML::Node& s, const std::string& w,
                 acquire::StripeConfig& o) {
    const std::string sw = w + ".stripe";
    y.expect_map(
        s, sw,
        {"max_value", "saturation_level", "min_peak", "window_half_width", "background_band",
         "gaussian_refinement", "double_peak_ratio", "double_peak_min_separation_px"});
    o.max_value = integer_in(y, s, sw, "max_value", 1, 65535, o.max_value);
    o.saturation_level = integer_in(y, s, sw, "saturation_level", 0, 65535, o.saturation_level);
    o.min_peak = y.number_or(s, sw, "min_peak", o.min_peak);
    o.window_half_width = integer_in(y, s, sw, "window_half_width", 1, 64, o.window_half_width);
    o.background_band = integer_in(y, s, sw, "background_band", 0, 64, o.background_band);
    if (s["gaussian_refinement"])
        o.gaussian_refinement = y.boolean(s["gaussian_refinement"], sw + ".gaussian_refinement");
    o.double_peak_ratio = y.number_or(s, sw, "double_peak_ratio", o.double_peak_ratio);
    o.double_peak_min_separation_px = integer_in(y, s, sw, "double_peak_min_separation_px", 1, 4096,
                                                 o.double_peak_min_separation_px);
    if (auto ok = acquire::check_stripe_config(o); !ok) y.fail(s, sw + ": " + ok.error().message);
}

// camera.exposure_table: [°C, µs] pairs, checked as acquire::ExposureTable takes them.
void read_exposure_table(const YamlReader& y, const YAML::Node& t, const std::string& w,
                         std::vector<std::pair<double, double>>& table) {
    if (!t.IsSequence()) y.fail(t, w + ".exposure_table: expected a list of [°C, µs]");
    for (std::size_t i = 0; i < t.size(); ++i) {
        const auto v = y.numbers(t[i], w + ".exposure_table", 2);
        table.emplace_back(v[0], v[1]);
    }
    if (auto ok = acquire::ExposureTable::create(table); !ok)
        y.fail(t, w + ".exposure_table: " + ok.error().message);
}

void read_camera(const YamlReader& y, const YAML::Node& c, AcquisitionConfig& a) {
    const std::string w = "camera";
    y.expect_map(c, w,
                 {"id",
                  "mode",
                  "width",
                  "height",
                  "offset_x",
                  "offset_y",
                  "pixel_format",
                  "frame_rate_hz",
                  "exposure_us",
                  "trigger",
                  "trigger_source",
                  "packet_size",
                  "packet_resend",
                  "buffers",
                  "timeout_ms",
                  "max_timeouts",
                  "control_wait_ms",
                  "start_latency_ms",
                  "features",
                  "scan_s",
                  "speed_mm_s",
                  "line_rate_hz",
                  "clock_offset_ns",  // moved to the calibration: refused below, by name
                  "peaks",
                  "stripe",
                  "exposure_table"});
    auto& cam = a.camera;
    auto& scan = a.scan;
    cam.id = y.string(y.require(c, w, "id"), w + ".id");
    if (c["mode"]) {
        scan.frame_mode = y.string(c["mode"], w + ".mode");
        if (scan.frame_mode != "image" && scan.frame_mode != "peaks")
            y.fail(c["mode"], w + ".mode: must be image or peaks");
    }
    cam.width = integer_in(y, c, w, "width", 0, 65535, cam.width);
    cam.height = integer_in(y, c, w, "height", 0, 65535, cam.height);
    cam.offset_x = integer_in(y, c, w, "offset_x", 0, 65535, cam.offset_x);
    cam.offset_y = integer_in(y, c, w, "offset_y", 0, 65535, cam.offset_y);
    if (c["pixel_format"]) cam.pixel_format = y.string(c["pixel_format"], w + ".pixel_format");
    cam.frame_rate_hz = y.number_or(c, w, "frame_rate_hz", cam.frame_rate_hz);
    cam.exposure_us = y.number_or(c, w, "exposure_us", cam.exposure_us);
    if (c["trigger"]) {
        cam.trigger = y.string(c["trigger"], w + ".trigger");
        if (cam.trigger != "free" && cam.trigger != "software" && cam.trigger != "external")
            y.fail(c["trigger"], w + ".trigger: must be free, software or external");
    }
    if (c["trigger_source"])
        cam.trigger_source = y.string(c["trigger_source"], w + ".trigger_source");
    cam.packet_size = integer_in(y, c, w, "packet_size", 0, 16000, cam.packet_size);
    if (c["packet_resend"]) cam.packet_resend = y.boolean(c["packet_resend"], w + ".packet_resend");
    cam.n_buffers = integer_in(y, c, w, "buffers", 2, 1024, cam.n_buffers);
    cam.timeout_ms = integer_in(y, c, w, "timeout_ms", 1, 600000, cam.timeout_ms);
    cam.max_timeouts = integer_in(y, c, w, "max_timeouts", 1, 1000, cam.max_timeouts);
    cam.control_wait_ms = integer_in(y, c, w, "control_wait_ms", 0, 60000, cam.control_wait_ms);
    cam.start_latency_ms = integer_in(y, c, w, "start_latency_ms", 0, 10000, cam.start_latency_ms);
    if (const YAML::Node f = c["features"]) read_camera_features(y, f, w, cam);
    a.scan_s = positive(y, c, w, "scan_s", a.scan_s);
    scan.speed_mm_s = positive(y, c, w, "speed_mm_s", scan.speed_mm_s);
    scan.line_period_s = 1.0 / positive(y, c, w, "line_rate_hz", 1.0 / scan.line_period_s);
    if (c["clock_offset_ns"])
        y.fail(c["clock_offset_ns"], w + ".clock_offset_ns: the camera → accelerometer clock "
                                         "offset is measured now: clock_offset_ns in the "
                                         "calibration file (docs/calibration.md)");
    if (const YAML::Node p = c["peaks"]) read_peaks(y, p, w, scan);
    if (const YAML::Node s = c["stripe"]) read_stripe(y, s, w, scan.stripe);
    if (scan.frame_mode == "image") scan.offset_y_px = cam.offset_y;
    scan.offset_x_px = cam.offset_x;
    if (const YAML::Node t = c["exposure_table"]) read_exposure_table(y, t, w, a.exposure_table);
}

void read_endpoint(const YamlReader& y, const YAML::Node& p, const std::string& w,
                   HttpEndpointConfig& out) {
    y.expect_map(p, w, {"enabled", "bind_address", "port"});
    out.enabled = p["enabled"] ? y.boolean(p["enabled"], w + ".enabled") : true;
    if (p["bind_address"]) out.bind_address = y.string(p["bind_address"], w + ".bind_address");
    out.port = integer_in(y, p, w, "port", 0, 65535, out.port);
}

PipelineSettings read_pipeline(const YamlReader& y, const YAML::Node& p) {
    const std::string w = "pipeline";
    y.expect_map(p, w, {"compensation", "highpass_hz", "threads"});
    PipelineSettings s;
    if (p["compensation"]) s.compensate = y.boolean(p["compensation"], w + ".compensation");
    s.highpass_hz = positive(y, p, w, "highpass_hz", s.highpass_hz);
    if (s.highpass_hz > 50.0)  // the scans' vibration is 2-50 Hz (docs/compensation.md)
        y.fail(p["highpass_hz"], w + ".highpass_hz: at most 50 Hz");
    s.threads = integer_in(y, p, w, "threads", 0, 64, s.threads);  // as hotgauge measure's
    return s;
}

// A topic level: not empty, and none of MQTT's separators or wildcards.
std::string topic_level(const YamlReader& y, const YAML::Node& m, const char* key) {
    const std::string v = y.string(y.require(m, "mqtt", key), std::string("mqtt.") + key);
    if (!plant::valid_topic_level(v))
        y.fail(m[key],
               std::string("mqtt.") + key + ": a topic level: not empty, without '/', '+' or '#'");
    return v;
}

void read_mqtt_tls(const YamlReader& y, const YAML::Node& t, const fs::path& base,
                   plant::MqttTls& out) {
    const std::string w = "mqtt.tls";
    y.expect_map(t, w, {"ca_file", "cert_file", "key_file"});
    out.ca_file = existing(y, y.require(t, w, "ca_file"), w + ".ca_file", base);
    if (t["cert_file"].IsDefined() != t["key_file"].IsDefined())
        y.fail(t, w + ": a client certificate needs both cert_file and key_file");
    if (t["cert_file"]) out.cert_file = existing(y, t["cert_file"], w + ".cert_file", base);
    if (t["key_file"]) out.key_file = existing(y, t["key_file"], w + ".key_file", base);
}

plant::MqttConfig read_mqtt(const YamlReader& y, const YAML::Node& m, const fs::path& base,
                            const fs::path& results_dir) {
    const std::string w = "mqtt";
    y.expect_map(m, w,
                 {"host", "port", "site", "cell", "client_id", "username", "password_file", "tls",
                  "keepalive_s", "retry_min_s", "retry_max_s", "spool_dir", "spool_max_mb"});
    plant::MqttConfig c;
    c.enabled = true;
    c.host = y.string(y.require(m, w, "host"), w + ".host");
    c.port = integer_in(y, m, w, "port", 1, 65535, m["tls"] ? 8883 : 1883);
    c.site = topic_level(y, m, "site");
    c.cell = topic_level(y, m, "cell");
    if (m["client_id"]) c.client_id = y.string(m["client_id"], w + ".client_id");
    if (m["username"]) c.username = y.string(m["username"], w + ".username");
    if (m["password_file"]) {
        if (c.username.empty()) y.fail(m["password_file"], w + ".password_file: needs a username");
        c.password_file = existing(y, m["password_file"], w + ".password_file", base);
    }
    if (const YAML::Node t = m["tls"]) read_mqtt_tls(y, t, base, c.tls);
    c.keepalive_s = integer_in(y, m, w, "keepalive_s", 5, 3600, c.keepalive_s);
    c.retry_min_s = positive(y, m, w, "retry_min_s", c.retry_min_s);
    c.retry_max_s = positive(y, m, w, "retry_max_s", c.retry_max_s);
    if (c.retry_max_s < c.retry_min_s)
        y.fail(m["retry_max_s"] ? m["retry_max_s"] : m, w + ".retry_max_s: less than retry_min_s");
    c.spool.dir = m["spool_dir"] ? base / y.string(m["spool_dir"], w + ".spool_dir")
                                 : results_dir / "mqtt-spool";
    c.spool.max_bytes =
        static_cast<std::uint64_t>(integer_in(y, m, w, "spool_max_mb", 1, 1'000'000, 256)) << 20;
    return c;
}

// recipes: PLC recipe slot -> recipe file; at least one.
void read_recipes(const YamlReader& y, const YAML::Node& root, const fs::path& base,
                  std::map<int, fs::path>& recipes_out) {
    const YAML::Node recipes = y.require(root, "hotgauged", "recipes");
    if (!recipes.IsMap() || recipes.size() == 0)
        y.fail(recipes, "recipes: expected slot: file pairs (slot 1..65535)");
    for (const auto& kv : recipes) {
        const auto slot = y.integer(kv.first, "recipes: slot");
        if (slot < 1 || slot > 65535) y.fail(kv.first, "recipes: slot must be in 1..65535");
        recipes_out[static_cast<int>(slot)] = existing(y, kv.second, "recipes", base);
    }
}

// models: and masters: slot -> file, each slot one that has a recipe; `pairs` names the file in
// the message ("file", "certificate").
void read_slot_files(const YamlReader& y, const YAML::Node& m, const std::string& what,
                     const std::string& pairs, const std::map<int, fs::path>& recipes,
                     const fs::path& base, std::map<int, fs::path>& out) {
    if (!m.IsMap()) y.fail(m, what + ": expected slot: " + pairs + " pairs");
    for (const auto& kv : m) {
        const auto slot = static_cast<int>(y.integer(kv.first, what + ": slot"));
        if (!recipes.count(slot))
            y.fail(kv.first, what + ": slot " + std::to_string(slot) + " has no recipe");
        out[slot] = existing(y, kv.second, what, base);
    }
}

// faces: the scan order; without it all four.
std::vector<std::string> read_faces(const YamlReader& y, const YAML::Node& root) {
    std::vector<std::string> faces =
        root["faces"] ? y.strings(root["faces"], "faces")
                      : std::vector<std::string>{"top", "bottom", "side1", "side2"};
    if (faces.empty()) y.fail(root["faces"], "faces: at least one face");
    if (std::set<std::string>(faces.begin(), faces.end()).size() != faces.size())
        y.fail(root["faces"], "faces: a face is listed twice");
    return faces;
}

void read_accelerometer(const YamlReader& y, const YAML::Node& a, DaemonConfig& c) {
    const std::string w = "accelerometer";
    y.expect_map(
        a, w,
        {"source", "bind", "sensor_id", "device_dir", "buffer_path", "margin_s", "sample_rate_hz"});
    const std::string source = y.string(y.require(a, w, "source"), w + ".source");
    c.accel_margin_s = positive(y, a, w, "margin_s", c.accel_margin_s);
    c.accel_rate_hz = positive(y, a, w, "sample_rate_hz", c.accel_rate_hz);
    if (source == "none") return;
    auto kind = accel::parse_accel_source_kind(source);
    if (!kind || *kind == accel::AccelSourceKind::recording)
        y.fail(a["source"], w + ".source: must be udp, iio or none");
    accel::AccelSourceConfig s;
    s.kind = *kind;
    if (a["bind"]) s.udp.bind = y.string(a["bind"], w + ".bind");
    if (a["sensor_id"])
        s.udp.sensor_id = static_cast<std::uint16_t>(integer_in(y, a, w, "sensor_id", 0, 65535, 0));
    if (a["device_dir"]) s.iio.device_dir = y.string(a["device_dir"], w + ".device_dir");
    if (a["buffer_path"]) s.iio.buffer_path = y.string(a["buffer_path"], w + ".buffer_path");
    if (auto ok = accel::validate(s); !ok) y.fail(a, w + ": " + ok.error().message);
    c.accelerometer = s;
}

// axis: a position for every face the cell scans (`faces`, read before).
void read_axis(const YamlReader& y, const YAML::Node& x, const std::vector<std::string>& faces,
               AxisConfig& o) {
    const std::string w = "axis";
    y.expect_map(x, w, {"kind", "address", "unit_id", "faces", "timeout_ms"});
    o.kind = y.string(y.require(x, w, "kind"), w + ".kind");
    if (o.kind != "none" && o.kind != "modbus")
        y.fail(x["kind"], w + ".kind: must be modbus or none");
    if (o.kind != "modbus") return;
    o.address = y.string(y.require(x, w, "address"), w + ".address");
    if (!accel::parse_host_port(o.address, w + ".address"))
        y.fail(x["address"], w + ".address: expected HOST:PORT");
    o.unit_id = integer_in(y, x, w, "unit_id", 0, 255, o.unit_id);
    o.timeout_ms = integer_in(y, x, w, "timeout_ms", 100, 600000, o.timeout_ms);
    const YAML::Node f = y.require(x, w, "faces");
    if (!f.IsMap()) y.fail(f, w + ".faces: expected face: position pairs");
    for (const auto& kv : f) {
        const std::string face = y.string(kv.first, w + ".faces");
        o.faces[face] = static_cast<int>(y.integer(kv.second, w + ".faces." + face));
    }
    for (const auto& face : faces)
        if (!o.faces.count(face)) y.fail(f, w + ".faces: no position for face '" + face + "'");
}

// results: the results log, the archive and the quality feed's settings.
void read_results(const YamlReader& y, const YAML::Node& r, const fs::path& base, DaemonConfig& c) {
    const std::string w = "results";
    y.expect_map(r, w,
                 {"dir", "archive_dir", "archive_quota_gb", "archive_every_nth_ok", "sync",
                  "drift_baseline", "lot_report", "lot_report_every_s", "min_free_mb"});
    if (r["dir"]) c.results.dir = base / y.string(r["dir"], w + ".dir");
    if (r["archive_dir"]) c.archive.dir = base / y.string(r["archive_dir"], w + ".archive_dir");
    c.archive.quota_bytes = static_cast<std::uint64_t>(positive(y, r, w, "archive_quota_gb", 20.0) *
                                                       1024.0 * 1024.0 * 1024.0);
    c.archive.every_nth_ok =
        integer_in(y, r, w, "archive_every_nth_ok", 0, 1'000'000, c.archive.every_nth_ok);
    if (r["sync"]) c.results.sync = y.boolean(r["sync"], w + ".sync");
    if (r["lot_report"]) c.quality.lot_report = y.boolean(r["lot_report"], w + ".lot_report");
    c.quality.lot_report_every_s = integer_in(y, r, w, "lot_report_every_s", 0, 3600,
                                              static_cast<int>(c.quality.lot_report_every_s));
    const int baseline = integer_in(y, r, w, "drift_baseline", 0, 100'000,
                                    static_cast<int>(c.quality.drift_baseline));
    if (baseline > 0 && baseline < static_cast<int>(quality::kMinBaseline))
        y.fail(r["drift_baseline"], w + ".drift_baseline: 0 (no drift watch) or at least " +
                                        std::to_string(quality::kMinBaseline));
    c.quality.drift_baseline = static_cast<std::size_t>(baseline);
    c.results_min_free_mb =
        integer_in(y, r, w, "min_free_mb", 0, 1'000'000, static_cast<int>(c.results_min_free_mb));
}

}  // namespace

core::Result<DaemonConfig> parse_daemon_config(std::string_view text, const fs::path& file,
                                               const io::PathExists& exists) {
    const YamlReader y(file.string(), text, exists);
    return y.guarded<DaemonConfig>([&] {
        const YAML::Node root = y.load();
        y.expect_map(root, "hotgauged",
                     {"calibration", "calibration_interval_days", "faces", "recipes", "models",
                      "masters", "camera", "accelerometer", "axis", "plc", "pyrometer", "results",
                      "status_page", "metrics", "mqtt", "pipeline",
                      "cell"});  // cell: moved to the calibration, refused below by name
        DaemonConfig c;
        c.file = file;
        c.hash = text_hash(text);
        const fs::path base = file.parent_path();
        if (root["cell"])
            y.fail(root["cell"],
                   "cell: the daemon takes the cell's geometry from its "
                   "calibration now: calibration: FILE (docs/calibration.md)");
        c.calibration_file =
            existing(y, y.require(root, "hotgauged", "calibration"), "calibration", base);
        c.calibration_interval_days = integer_in(y, root, "hotgauged", "calibration_interval_days",
                                                 1, 3650, c.calibration_interval_days);
        read_recipes(y, root, base, c.recipes);
        if (const YAML::Node m = root["models"])
            read_slot_files(y, m, "models", "file", c.recipes, base, c.models);
        if (const YAML::Node m = root["masters"])
            read_slot_files(y, m, "masters", "certificate", c.recipes, base, c.masters);
        c.faces = read_faces(y, root);
        read_camera(y, y.require(root, "hotgauged", "camera"), c.acquisition);
        if (const YAML::Node a = root["accelerometer"]) read_accelerometer(y, a, c);
        if (const YAML::Node x = root["axis"]) read_axis(y, x, c.faces, c.axis);
        if (const YAML::Node p = root["plc"]) read_plc_server(y, p, "plc", c.plc);
        if (const YAML::Node p = root["pyrometer"]) {
            plc::PyrometerConfig py;
            read_pyrometer(y, p, "pyrometer", py);
            c.pyrometer = py;
        }
        if (const YAML::Node r = root["results"]) read_results(y, r, base, c);
        if (const YAML::Node p = root["status_page"])
            read_endpoint(y, p, "status_page", c.status_page);
        if (const YAML::Node p = root["metrics"]) read_endpoint(y, p, "metrics", c.metrics);
        if (const YAML::Node p = root["pipeline"]) c.pipeline = read_pipeline(y, p);
        if (const YAML::Node m = root["mqtt"]) c.mqtt = read_mqtt(y, m, base, c.results.dir);
        return c;
    });
}

core::Result<DaemonConfig> read_daemon_config(const fs::path& file) {
    return io::parse_file(file, [](std::string_view text, const fs::path& f) {
        return parse_daemon_config(text, f);
    });
}

}  // namespace hotgauge::cell
