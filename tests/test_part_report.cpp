// The part report (docs/results.md "Part report"): a simulated hot part whose flange top stands
// 0.2 mm above the drawing shows +0.2 mm (grown to the part's temperature) on that surface and
// about 0 elsewhere; the page is self-contained, has one range image and one deviation map per
// face and one band per feature, and never prints a number for a value that was not measured.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "hotgauge/io/recipe.hpp"
#include "hotgauge/pipeline/pipeline.hpp"
#include "hotgauge/report/part_report.hpp"
#include "hotgauge/results/read_back.hpp"
#include "hotgauge/sim/simulator.hpp"

namespace fs = std::filesystem;
using namespace hotgauge;

namespace {

constexpr double kRaised_mm = 0.2;       // the forged flange top above the drawing (cold)
constexpr double kVibrationScale = 5.0;  // the press modes' amplitudes

struct Env {
    core::Recipe recipe;  // the drawing
    sim::SimResult sim;   // a part forged with its flange top raised, without side2
    pipeline::PartResult result;
    double growth = 1;
};

// hub-a forged with flange_top 0.2 mm high and every other dimension nominal, scanned at 900 °C
// in the quick cell under strong vibration without face side2 (so that its two heights are not
// measured), measured in the true pose (matching would take a little of the step into the pose).
const Env& env() {
    static const Env e = [] {
        Env out;
        auto recipe = io::read_recipe(HOTGAUGE_SOURCE_DIR "/config/parts/hub-a.yaml");
        auto cell = sim::read_cell_config(HOTGAUGE_SOURCE_DIR "/config/cell.yaml");
        if (!recipe || !cell) std::abort();
        out.recipe = *recipe;
        core::Recipe forged = *recipe;
        for (auto& [name, z] : forged.levels_mm)
            if (name == "flange_top") z += kRaised_mm;
        sim::SimOptions o;
        o.seed = 7;
        o.temperature_c = 900;
        o.dimension_sigma_mm = 0;
        o.part_id = "REPORT 1/A";
        o.captured_at = "2026-12-04T10:00:00Z";
        o.t0_ns = 1'790'000'000'000'000'000;
        o.faces = {"top", "bottom", "side1"};
        sim::CellConfig quick = sim::quick(*cell);
        // Strong blows, so that a map drawn without the compensation would show them (|d| 95 %
        // 0.32 mm elsewhere instead of 0.10).
        for (auto& mode : quick.vibration.modes) mode.amplitude_mm *= kVibrationScale;
        auto s = sim::simulate(forged, quick, o);
        if (!s) std::abort();
        out.sim = std::move(*s);
        pipeline::PipelineOptions p;
        p.T_world_part = out.sim.truth.T_world_part;
        p.pose_source = "truth";
        out.result = pipeline::run(out.sim.recording, out.recipe, p);
        out.growth = out.sim.truth.growth;
        return out;
    }();
    return e;
}

report::DeviationMap face_map(const std::string& face) {
    const auto& e = env();
    const auto* scan = e.sim.recording.face(face);
    EXPECT_NE(scan, nullptr);
    const auto u = e.result.displacement_mm.find(face);
    EXPECT_NE(u, e.result.displacement_mm.end()) << face << " not compensated";
    EXPECT_DOUBLE_EQ(report::hot_scale(e.result), e.growth);
    const auto nominal = core::AxisymmetricSolid::from_recipe(e.recipe, {}, {}, e.growth);
    return report::deviation_map(*scan, &u->second, *e.result.T_world_part, nominal);
}

double quantile(std::vector<double> v, double q) {
    if (v.empty()) return NAN;
    auto at = v.begin() + static_cast<std::ptrdiff_t>(q * static_cast<double>(v.size() - 1));
    std::nth_element(v.begin(), at, v.end());
    return *at;
}

std::size_t count(const std::string& text, const std::string& what) {
    std::size_t n = 0;
    for (auto at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
    return n;
}

// The <tr> of one feature in the page.
std::string feature_row(const std::string& html, const std::string& name) {
    const auto from = html.find("data-feature=\"" + name + "\"");
    if (from == std::string::npos) return "";
    return html.substr(from, html.find("</tr>", from) - from);
}

// The content of <td class="cls"> in a row.
std::string cell(const std::string& row, const std::string& cls) {
    const std::string open = "<td class=\"" + cls + "\">";
    const auto from = row.find(open);
    if (from == std::string::npos) return "(no cell " + cls + ")";
    const auto begin = from + open.size();
    return row.substr(begin, row.find("</td>", begin) - begin);
}

}  // namespace

// On the top face, the raised flange top (away from its edges) deviates by +0.2 mm × growth;
// every other point of the part within the noise of 0 (σ 0.05 mm).
TEST(DeviationMap, RaisedFlangeTopShowsItsStepAndTheRestIsNominal) {
    const auto& e = env();
    const double g = e.growth, z_top = (62.0 + kRaised_mm) * g;
    std::vector<double> on_step, elsewhere;
    std::size_t off_part = 0;
    for (const std::string face : {"top", "bottom", "side1"}) {
        const report::DeviationMap m = face_map(face);
        ASSERT_EQ(m.kind.size(), static_cast<std::size_t>(m.profiles * m.width));
        for (std::size_t px = 0; px < m.kind.size(); ++px) {
            if (m.kind[px] == report::PixelKind::kOffPart) ++off_part;
            if (m.kind[px] != report::PixelKind::kPart) continue;
            const double r = m.r_mm[px], z = m.z_mm[px], d = m.deviation_mm[px];
            if (face == "top" && std::abs(z - z_top) < 0.15 && r > 37 * g && r < 67 * g)
                on_step.push_back(d);
            else if (std::abs(z - 62.0 * g) > 1.0)
                elsewhere.push_back(std::abs(d));
        }
    }
    std::printf(
        "flange top: %zu points, median %+.4f mm (expected %+.4f); elsewhere: %zu points, "
        "|deviation| median %.4f, 95 %% %.4f mm; %zu off the part\n",
        on_step.size(), quantile(on_step, 0.5), kRaised_mm * g, elsewhere.size(),
        quantile(elsewhere, 0.5), quantile(elsewhere, 0.95), off_part);
    ASSERT_GT(on_step.size(), 500u);
    EXPECT_NEAR(quantile(on_step, 0.5), kRaised_mm * g, 0.01);
    EXPECT_GT(quantile(on_step, 0.05), 0.1);  // the whole surface, not its median only
    ASSERT_GT(elsewhere.size(), on_step.size());
    EXPECT_LT(quantile(elsewhere, 0.5), 0.05);
    EXPECT_LT(quantile(elsewhere, 0.95), 0.15);
    EXPECT_GT(off_part, 1000u);  // the support plate in view is not part of the map's scale
}

// Pixel (k, i) is profile k's point i, moved by profile k's displacement: the map against a
// direct computation from FaceScan::nominal_world_point, every pixel of every face.
TEST(DeviationMap, EachPixelIsItsProfilePointMovedByItsDisplacement) {
    const auto& e = env();
    const auto nominal = core::AxisymmetricSolid::from_recipe(e.recipe, {}, {}, e.growth);
    const Eigen::Isometry3d T_part_world = e.result.T_world_part->inverse();
    std::size_t points = 0;
    for (const auto& face : e.sim.recording.faces) {
        const report::DeviationMap m = face_map(face.name);
        const auto& u = e.result.displacement_mm.at(face.name);
        for (std::int64_t k = 0; k < face.n_profiles(); ++k)
            for (std::int64_t i = 0; i < face.width; ++i) {
                const auto px = static_cast<std::size_t>(k * face.width + i);
                if (std::isnan(face.x(k, i)) || std::isnan(face.z(k, i))) {
                    ASSERT_EQ(m.kind[px], report::PixelKind::kNoPoint);
                    continue;
                }
                ASSERT_NE(m.kind[px], report::PixelKind::kNoPoint);
                const Eigen::Vector3d p = T_part_world * (face.nominal_world_point(k, i) +
                                                          u[static_cast<std::size_t>(k)]);
                const double r = std::hypot(p.x(), p.y());
                ASSERT_NEAR(m.r_mm[px], r, 1e-4);
                ASSERT_NEAR(m.z_mm[px], p.z(), 1e-4);
                if (m.kind[px] != report::PixelKind::kPart) continue;
                const double d = nominal.distance(p);
                ASSERT_NEAR(m.deviation_mm[px], nominal.inside(r, p.z()) ? -d : d, 1e-4);
                ++points;
            }
    }
    EXPECT_GT(points, 30'000u);
}

// The page: everything inline, the expected pictures and bands, "not measured" in words.
TEST(PartReport, IsSelfContainedWithOnePictureEachAndNoNumberForWhatIsNotMeasured) {
    const auto& e = env();
    const auto html = report::part_report_html(e.sim.recording, e.recipe, e.result);
    ASSERT_TRUE(html) << html.error().message;
    // Every reference: an attribute src= or href= (std::regex overflows its stack on the
    // pictures' base64, hence the plain search).
    std::size_t refs = 0;
    for (const std::string attribute : {"src=", "href="})
        for (auto at = html->find(attribute); at != std::string::npos;
             at = html->find(attribute, at + 1), ++refs) {
            const std::string value = html->substr(at + attribute.size(), 8);
            EXPECT_TRUE(value.rfind("\"data:", 0) == 0 || value.rfind("\"#", 0) == 0) << value;
        }
    const std::size_t faces = e.sim.recording.faces.size(), features = e.recipe.features.size();
    EXPECT_EQ(refs, 2 * faces);
    EXPECT_EQ(html->find("http"), std::string::npos);
    EXPECT_EQ(html->find("<script"), std::string::npos);
    EXPECT_EQ(count(*html, "url("), count(*html, "url(#"));
    EXPECT_EQ(count(*html, "<img "), 2 * faces);  // range image and deviation map
    // Per face the labels over the map and the colour legend; per feature its band.
    EXPECT_EQ(count(*html, "<svg "), 2 * faces + features);
    EXPECT_EQ(count(*html, "<svg class=\"band\""), features);
    EXPECT_NE(html->find("<h1>Part REPORT 1/A</h1>"), std::string::npos);

    // side2 was not scanned: its heights are not measured, and say so in words only.
    for (const char* name : {"Height 3 side2", "Height 4 side2"}) {
        const std::string row = feature_row(*html, name);
        ASSERT_FALSE(row.empty()) << name;
        for (const char* cls : {"cold", "dev", "u"}) {
            EXPECT_EQ(cell(row, cls), "not measured") << name << " " << cls;
        }
        const std::string band = cell(row, "band");
        EXPECT_NE(band.find(">not measured</text>"), std::string::npos) << band;
        EXPECT_EQ(band.find("class=\"value"), std::string::npos) << band;
    }
    // A measured one: its value, signed deviation and marker.
    const std::string row = feature_row(*html, "Height 3 side1");
    // "62.213" and "+0.213": digits, a point, three decimals (a sign first for the deviation).
    const auto three_decimals = [](const std::string& v, bool sign) {
        const std::size_t from = sign ? 1 : 0, point = v.find('.');
        if (v.size() < from + 5 || (sign && v[0] != '+' && v[0] != '-')) return false;
        if (point == std::string::npos || point == from || v.size() - point != 4) return false;
        for (std::size_t i = from; i < v.size(); ++i)
            if (i != point && !std::isdigit(static_cast<unsigned char>(v[i]))) return false;
        return true;
    };
    EXPECT_TRUE(three_decimals(cell(row, "cold"), false)) << cell(row, "cold");
    EXPECT_TRUE(three_decimals(cell(row, "dev"), true)) << cell(row, "dev");
    EXPECT_NE(cell(row, "band").find("<circle class=\"value\""), std::string::npos);
    // The raised flange top is Height 3's upper end on side1: its level is outlined there.
    EXPECT_NE(html->find("Height 3 side1: flange_top"), std::string::npos);
}

// Without a pose (part not found) there is nothing to compare the scan with: the range images
// and the table only, and the reason.
TEST(PartReport, WithoutAPoseHasRangeImagesAndTheReason) {
    const auto& e = env();
    pipeline::PartResult r = e.result;
    r.T_world_part.reset();
    r.match = match::MatchResult{};
    r.match->reason = "part not found: best score 0.412";
    const auto html = report::part_report_html(e.sim.recording, e.recipe, r);
    ASSERT_TRUE(html) << html.error().message;
    const std::size_t faces = e.sim.recording.faces.size();
    EXPECT_EQ(count(*html, "<img "), faces);
    EXPECT_EQ(count(*html, "<svg "), e.recipe.features.size());
    EXPECT_EQ(count(*html, "No deviation map: part not found: best score 0.412."), faces);
}

// The status page's picture: a PNG of the range image at the whole step that fits the asked
// side (the full image at step 1), no bytes for a face without profiles.
TEST(RangePng, IsTheRangeImageAtAWholeStepWithinTheSide) {
    const auto& scan = *env().sim.recording.face("top");
    const auto full = report::range_png(scan, 1 << 20);
    const auto small = report::range_png(scan, 100);
    EXPECT_EQ(small.face, "top");
    EXPECT_EQ(full.width, scan.width);
    EXPECT_EQ(full.height, scan.n_profiles());
    const int longer = static_cast<int>(std::max<std::int64_t>(scan.width, scan.n_profiles()));
    const int step = (longer + 99) / 100;
    EXPECT_EQ(small.width, (full.width + step - 1) / step);
    EXPECT_EQ(small.height, (full.height + step - 1) / step);
    EXPECT_LE(std::max(small.width, small.height), 100);
    // The PNG's signature and its header's size (RFC 2083: IHDR width, height big-endian).
    ASSERT_GT(small.png.size(), 24u);
    EXPECT_EQ(std::string(small.png.begin() + 1, small.png.begin() + 4), "PNG");
    const auto be32 = [&](std::size_t at) {
        return (small.png[at] << 24) | (small.png[at + 1] << 16) | (small.png[at + 2] << 8) |
               small.png[at + 3];
    };
    EXPECT_EQ(be32(16), small.width);
    EXPECT_EQ(be32(20), small.height);
    EXPECT_TRUE(report::range_png(core::FaceScan{}, 100).png.empty());
}

// A value beyond the drawn range sits at the band's edge as an arrow, not off the picture.
TEST(PartReport, ValueFarOutOfToleranceIsClampedToTheEdge) {
    const auto& e = env();
    pipeline::PartResult r = e.result;
    auto& f = r.measurement.features.front();
    ASSERT_TRUE(f.cold_mm);
    f.cold_mm = f.nominal_mm + 5.0;
    f.deviation_mm = 5.0;
    f.verdict = measure::Verdict::kNok;
    const auto html = report::part_report_html(e.sim.recording, e.recipe, r);
    ASSERT_TRUE(html) << html.error().message;
    const std::string band = cell(feature_row(*html, f.name), "band");
    EXPECT_NE(band.find("class=\"value outside clamped\" points=\"198,14"), std::string::npos)
        << band;
}

// A result that is not of this recording is an error naming the part and the face.
TEST(PartReport, ResultOfAnotherRecordingIsAnError) {
    const auto& e = env();
    pipeline::PartResult r = e.result;
    r.displacement_mm["top"].pop_back();
    auto html = report::part_report_html(e.sim.recording, e.recipe, r);
    ASSERT_FALSE(html);
    EXPECT_NE(html.error().message.find("face top"), std::string::npos) << html.error().message;
    r = e.result;
    r.faces.push_back({});
    r.faces.back().name = "side2";
    html = report::part_report_html(e.sim.recording, e.recipe, r);
    ASSERT_FALSE(html);
    EXPECT_NE(html.error().message.find("'side2'"), std::string::npos) << html.error().message;
}

// `report part --results DIR --sequence N` finds the recording through the day files'
// archived_as (docs/results.md); the last line of a repeated sequence counts.
TEST(ArchivedRecording, FoundBySequenceWithClearErrorsOtherwise) {
    const fs::path dir =
        fs::temp_directory_path() / ("hotgauge_report_" + std::to_string(getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir / "archive" / "2026-12-04" / "000000000005_P5");
    {
        std::ofstream day(dir / "2026-12-04.jsonl");
        day << R"({"sequence": 5, "archived_as": null, "part": {}})"
            << "\n"
            << R"({"sequence": 5, "archived_as": "archive/2026-12-04/000000000005_P5", "part": {}})"
            << "\n"
            << R"({"sequence": 6, "archived_as": null, "part": {}})"
            << "\n"
            << R"({"sequence": 7, "archived_as": "archive/2026-12-03/000000000007_P7", "part": {}})"
            << "\n";
    }
    auto found = results::archived_recording(dir, 5);
    ASSERT_TRUE(found) << found.error().message;
    EXPECT_EQ(fs::canonical(*found), fs::canonical(dir / "archive/2026-12-04/000000000005_P5"));

    auto err = results::archived_recording(dir, 6);
    ASSERT_FALSE(err);
    EXPECT_NE(err.error().message.find("2026-12-04.jsonl:3: part sequence 6 was not archived"),
              std::string::npos)
        << err.error().message;
    err = results::archived_recording(dir, 7);
    ASSERT_FALSE(err);
    EXPECT_NE(err.error().message.find("which is gone"), std::string::npos) << err.error().message;
    err = results::archived_recording(dir, 8);
    ASSERT_FALSE(err);
    EXPECT_NE(err.error().message.find("no part sequence 8 in the results"), std::string::npos)
        << err.error().message;
    fs::remove_all(dir);
}
