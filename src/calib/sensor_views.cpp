// The sensor calibration's views file and its images (docs/calibration.md "Sensor").
#include <opencv2/imgcodecs.hpp>

#include "hotgauge/calib/sensor.hpp"
#include "hotgauge/io/yaml_reader.hpp"
#include "hotgauge/io/yaml_writer.hpp"

namespace hotgauge::calib {
namespace {

constexpr const char* kFormat = "hotgauge-sensor-views-1";

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

}  // namespace

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
            const cv::Mat m(img->height, img->width, CV_8UC1,
                            const_cast<std::uint8_t*>(img->pixels.data()));
            if (!cv::imwrite((dir / name).string(), m))
                return core::make_error((dir / name).string() + ": cannot write");
            y += std::string(img == &s.views[i].board ? "board: " : ", laser: ") + name;
        }
        y += "}\n";
    }
    return io::write_text(dir / "views.yaml", y);
}

}  // namespace hotgauge::calib
