// The sensor calibration's files and their images: the views file (image mode) and the stage
// file (docs/calibration.md "Sensor", "Sensor on a stage").
#include <cmath>
#include <opencv2/imgcodecs.hpp>

#include "hotgauge/calib/sensor.hpp"
#include "hotgauge/calib/sensor_stage.hpp"
#include "hotgauge/io/yaml_reader.hpp"
#include "hotgauge/io/yaml_writer.hpp"

namespace hotgauge::calib {
namespace {

constexpr const char* kFormat = "hotgauge-sensor-views-1";
constexpr const char* kStageFormat = "hotgauge-sensor-stage-1";

// An 8-bit grey PNG (or any format OpenCV reads), empty when it cannot be read.
GrayImage read_image(const std::filesystem::path& file) {
    const cv::Mat m = cv::imread(file.string(), cv::IMREAD_GRAYSCALE);
    GrayImage g;
    if (m.empty() || m.depth() != CV_8U) return g;
    g.width = m.cols;
    g.height = m.rows;
    g.pixels.resize(static_cast<std::size_t>(m.cols) * m.rows);
    for (int r = 0; r < m.rows; ++r)
        std::copy(m.ptr<std::uint8_t>(r), m.ptr<std::uint8_t>(r) + m.cols,
                  g.pixels.begin() + static_cast<std::ptrdiff_t>(r) * m.cols);
    return g;
}

core::Result<void> write_png(const GrayImage& img, const std::filesystem::path& file) {
    const cv::Mat m(img.height, img.width, CV_8UC1, const_cast<std::uint8_t*>(img.pixels.data()));
    if (!cv::imwrite(file.string(), m)) return core::make_error(file.string() + ": cannot write");
    return {};
}

}  // namespace

core::Result<std::vector<StageReading>> read_sensor_stage(const std::filesystem::path& file) {
    const io::YamlReader y(file.string());
    const std::filesystem::path dir = file.parent_path();
    return y.guarded<std::vector<StageReading>>([&] {
        const YAML::Node root = y.load();
        y.expect_map(root, "stage file", {"format", "readings"});
        const std::string format = y.string(y.require(root, "stage file", "format"), "format");
        if (format != kStageFormat)
            y.fail(root["format"], "format: '" + format + "', expected " + kStageFormat);
        const YAML::Node list = y.require(root, "stage file", "readings");
        if (!list.IsSequence()) y.fail(list, "readings: expected a list");
        std::vector<StageReading> out;
        for (std::size_t i = 0; i < list.size(); ++i) {
            const std::string w = "readings[" + std::to_string(i) + "]";
            y.expect_map(list[i], w, {"laser", "height_mm", "tilt_deg"});
            StageReading r;
            const std::string name = y.string(y.require(list[i], w, "laser"), w + ".laser");
            r.laser = read_image(dir / name);
            if (r.laser.empty())
                y.fail(list[i]["laser"],
                       w + ".laser: cannot read '" + name + "' as an 8-bit grey image");
            if (!out.empty() && (r.laser.width != out.front().laser.width ||
                                 r.laser.height != out.front().laser.height))
                y.fail(list[i]["laser"], w + ".laser: '" + name + "' is not the size of the first");
            r.height_mm = y.number(y.require(list[i], w, "height_mm"), w + ".height_mm");
            if (!(r.height_mm > 0.0)) y.fail(list[i]["height_mm"], w + ".height_mm: must be > 0");
            r.tilt_deg = y.number(y.require(list[i], w, "tilt_deg"), w + ".tilt_deg");
            if (!(std::abs(r.tilt_deg) < 60.0) || (r.tilt_deg != 0.0 && std::abs(r.tilt_deg) < 5.0))
                y.fail(list[i]["tilt_deg"],
                       w + ".tilt_deg: 0 (level) or 5° to 60° either way (tilted)");
            out.push_back(std::move(r));
        }
        return out;
    });
}

core::Result<void> write_sensor_stage(const std::vector<StageReading>& readings,
                                      const std::filesystem::path& dir) {
    std::error_code ec;
    std::filesystem::create_directories(dir, ec);
    if (ec) return core::make_error(dir.string() + ": " + ec.message());
    std::string y = std::string("format: ") + kStageFormat + "\nreadings:\n";
    for (std::size_t i = 0; i < readings.size(); ++i) {
        char name[32];
        std::snprintf(name, sizeof name, "stage%02zu.png", i + 1);
        if (auto w = write_png(readings[i].laser, dir / name); !w) return w;
        y += std::string("  - {laser: ") + name +
             ", height_mm: " + io::fmt_double(readings[i].height_mm) +
             ", tilt_deg: " + io::fmt_double(readings[i].tilt_deg) + "}\n";
    }
    return io::write_text(dir / "stage.yaml", y);
}

core::Result<SensorViews> read_sensor_views(const std::filesystem::path& file) {
    const io::YamlReader y(file.string());
    const std::filesystem::path dir = file.parent_path();
    return y.guarded<SensorViews>([&] {
        const YAML::Node root = y.load();
        y.expect_map(root, "views file", {"format", "board", "views"});
        const std::string format = y.string(y.require(root, "views file", "format"), "format");
        if (format != kFormat)
            y.fail(root["format"], "format: '" + format + "', expected " + kFormat);
        SensorViews out;
        const YAML::Node b = y.require(root, "views file", "board");
        y.expect_map(b, "board", {"cols", "rows", "square_mm"});
        out.board.cols = static_cast<int>(y.integer(y.require(b, "board", "cols"), "board.cols"));
        out.board.rows = static_cast<int>(y.integer(y.require(b, "board", "rows"), "board.rows"));
        out.board.square_mm = y.number(y.require(b, "board", "square_mm"), "board.square_mm");
        if (out.board.cols < 3 || out.board.rows < 3 || !(out.board.square_mm > 0))
            y.fail(b, "board: at least 3 × 3 inner corners and a positive square_mm");
        const YAML::Node views = y.require(root, "views file", "views");
        if (!views.IsSequence()) y.fail(views, "views: expected a list");
        for (std::size_t i = 0; i < views.size(); ++i) {
            const std::string w = "views[" + std::to_string(i) + "]";
            y.expect_map(views[i], w, {"board", "laser"});
            TargetView v;
            for (const char* key : {"board", "laser"}) {
                if (!views[i][key]) continue;
                const std::string name = y.string(views[i][key], w + "." + key);
                GrayImage img = read_image(dir / name);
                if (img.empty())
                    y.fail(views[i][key],
                           w + "." + key + ": cannot read '" + name + "' as an 8-bit grey image");
                (std::string(key) == "board" ? v.board : v.laser) = std::move(img);
            }
            if (v.board.empty()) y.fail(views[i], w + ": no board image");
            out.views.push_back(std::move(v));
        }
        return out;
    });
}

core::Result<void> write_sensor_views(const SensorViews& s, const std::filesystem::path& dir) {
    std::error_code ec;
    std::filesystem::create_directories(dir, ec);
    if (ec) return core::make_error(dir.string() + ": " + ec.message());
    std::string y = std::string("format: ") + kFormat +
                    "\nboard: {cols: " + std::to_string(s.board.cols) +
                    ", rows: " + std::to_string(s.board.rows) +
                    ", square_mm: " + io::fmt_double(s.board.square_mm) + "}\nviews:\n";
    for (std::size_t i = 0; i < s.views.size(); ++i) {
        char stem[32];
        std::snprintf(stem, sizeof stem, "view%02zu", i + 1);
        y += "  - {";
        for (const auto* img : {&s.views[i].board, &s.views[i].laser}) {
            if (img->empty()) continue;
            const std::string name =
                std::string(stem) + (img == &s.views[i].board ? "-board.png" : "-laser.png");
            if (auto w = write_png(*img, dir / name); !w) return w;
            y += std::string(img == &s.views[i].board ? "board: " : ", laser: ") + name;
        }
        y += "}\n";
    }
    return io::write_text(dir / "views.yaml", y);
}

}  // namespace hotgauge::calib
