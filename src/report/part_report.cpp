#include "hotgauge/report/part_report.hpp"

#include <algorithm>
#include <cmath>

#include "hotgauge/report/html.hpp"
#include "pictures.hpp"

namespace hotgauge::report {
namespace {

using measure::FeatureResult;
using measure::Verdict;

// The colour scale saturates at the largest tolerance of the recipe's features: a deviation that
// could decide a verdict shows in the full colour range, and noise stays near white.
double colour_scale_mm(const core::Recipe& recipe) {
    double s = 0;
    for (const auto& f : recipe.features)
        s = std::max({s, std::abs(f.tol_lower_mm), std::abs(f.tol_upper_mm)});
    return s > 0 ? s : 0.5;
}

const core::FeatureSpec* spec_of(const core::Recipe& recipe, const std::string& name) {
    for (const auto& f : recipe.features)
        if (f.name == name) return &f;
    return nullptr;
}

// The measured ends of heights and edges of diameters that `face` contributed to: what the fits
// found, in the hot part frame. A diameter's edge circle is drawn at its level's nominal height.
std::vector<Overlay> face_overlays(const core::Recipe& recipe, const measure::PartMeasurement& m,
                                   const std::string& face, double scale) {
    std::vector<Overlay> out;
    auto add = [&](const std::string& feature, Overlay o) {
        // One fitted end can serve several features (Heights 1 and 2 both end at spigot_end).
        for (auto& seen : out)
            if (seen.edge_circle == o.edge_circle && seen.what == o.what &&
                std::abs(seen.r_mm - o.r_mm) < 0.005 && std::abs(seen.z_mm - o.z_mm) < 0.005) {
                seen.features += ", " + feature;
                return;
            }
        o.features = feature;
        out.push_back(std::move(o));
    };
    for (const FeatureResult& f : m.features) {
        if (!f.hot_mm) continue;
        for (const auto& e : f.ends) {
            if (std::find(e.faces.begin(), e.faces.end(), face) == e.faces.end()) continue;
            if (f.kind == core::FeatureKind::kHeight) {
                add(f.name,
                    {"", e.level, e.level + " (" + e.estimator + ")", false, 0.0, e.value_mm});
                continue;
            }
            const core::FeatureSpec* spec = spec_of(recipe, f.name);
            const auto level = spec ? recipe.level(spec->edge_at) : std::nullopt;
            if (level)
                add(f.name, {"", e.level, e.level + " edge (" + e.estimator + ")", true, e.value_mm,
                             *level * scale});
        }
    }
    return out;
}

std::string verdict_span(Verdict v) {
    const std::string s = measure::to_string(v);
    return "<span class=\"verdict v-" + s + "\">" + s + "</span>";
}

// One feature's cold value on its tolerance band: the band from LSL to USL, the nominal tick,
// the value's marker. The drawn range is the band and half its width each side; a value beyond
// it is an arrow at the edge. No value: the text, never a marker.
std::string band_svg(const FeatureResult& f) {
    const double lo = f.nominal_mm + f.tol_lower_mm, hi = f.nominal_mm + f.tol_upper_mm;
    const double half = std::max(hi - lo, 1e-3) / 2, x0 = lo - half, x1 = hi + half;
    constexpr double kLeft = 8, kRight = 192;
    auto x = [&](double v) { return fixed(kLeft + (v - x0) / (x1 - x0) * (kRight - kLeft), 1); };
    std::string s =
        "<svg class=\"band\" width=\"200\" height=\"28\" viewBox=\"0 0 200 28\" role=\"img\">"
        "<line x1=\"8\" y1=\"14\" x2=\"192\" y2=\"14\" stroke=\"#999\"/>"
        "<rect x=\"" +
        x(lo) + "\" y=\"7\" width=\"" + fixed((hi - lo) / (x1 - x0) * 184, 1) +
        "\" height=\"14\" fill=\"#d9f0d3\" stroke=\"#5aae61\"/>"
        "<line class=\"nominal\" x1=\"" +
        x(f.nominal_mm) + "\" y1=\"3\" x2=\"" + x(f.nominal_mm) +
        "\" y2=\"25\" stroke=\"#333\" stroke-width=\"1.5\"/>";
    if (!f.cold_mm) {
        const char* text = f.hot_mm ? "no cold value" : "not measured";
        return s + "<text x=\"100\" y=\"18\" text-anchor=\"middle\" font-size=\"11\">" + text +
               "</text></svg>";
    }
    const double v = *f.cold_mm;
    const char* colour = f.verdict == Verdict::kNok        ? "#c62828"
                         : f.verdict == Verdict::kDegraded ? "#ef6c00"
                                                           : "#1b5e20";
    s += "<title>cold " + fixed(v, 3) + " mm, tolerance " + fixed(lo, 3) + " … " + fixed(hi, 3) +
         " mm</title>";
    // Outside the tolerance: a red ring whatever the verdict (a degraded value sorts nothing).
    const bool outside = v < lo || v > hi;
    const std::string cls = outside ? "value outside" : "value";
    const std::string paint = std::string("\" fill=\"") + colour + "\" stroke=\"" +
                              (outside ? "#c62828\" stroke-width=\"2\"" : "#fff\"");
    if (v < x0 || v > x1)
        s += "<polygon class=\"" + cls + " clamped\" points=\"" +
             (v < x0 ? "2,14 11,7 11,21" : "198,14 189,7 189,21") + paint + "/>";
    else
        s += "<circle class=\"" + cls + "\" cx=\"" + x(v) + "\" cy=\"14\" r=\"4.5" + paint + "/>";
    return s + "</svg>";
}

// A row of the feature table. A value that is not there is said in words, never shown as 0.
std::string feature_row(const FeatureResult& f) {
    auto cell = [](const char* cls, const std::string& text) {
        return std::string("<td class=\"") + cls + "\">" + text + "</td>";
    };
    const std::string missing = f.hot_mm ? "—" : "not measured";
    std::string cold = f.cold_mm  ? fixed(*f.cold_mm, 3)
                       : f.hot_mm ? "hot " + fixed(*f.hot_mm, 3) + " (temperature unknown)"
                                  : missing;
    std::string u = f.u_cold_mm ? fixed(*f.u_cold_mm, 4)
                    : f.hot_mm  ? fixed(f.u_mm, 4) + " (hot)"
                                : missing;
    return "<tr class=\"feature\" data-feature=\"" + escape(f.name) + "\">" +
           cell("name", escape(f.name)) + cell("nominal", fixed(f.nominal_mm, 3)) +
           cell("lower", fixed(f.tol_lower_mm, 3, true)) +
           cell("upper", fixed(f.tol_upper_mm, 3, true)) + cell("cold", cold) +
           cell("dev", f.deviation_mm ? fixed(*f.deviation_mm, 3, true) : missing) +
           cell("verdict", verdict_span(f.verdict)) + cell("u", u) + cell("band", band_svg(f)) +
           cell("reason", escape(f.reason)) + "</tr>\n";
}

std::string feature_table(const measure::PartMeasurement& m) {
    std::string s =
        "<table class=\"features\"><thead><tr><th>feature</th><th>nominal mm</th>"
        "<th>lower mm</th><th>upper mm</th><th>cold value mm</th><th>deviation mm</th>"
        "<th>verdict</th><th>u mm</th><th>on the tolerance band</th><th>reason</th></tr>"
        "</thead><tbody>\n";
    for (const auto& f : m.features) s += feature_row(f);
    return s + "</tbody></table>\n";
}

// The vertical colour scale of a deviation map, with its values in mm and the other colours of
// the picture. `id` keeps each legend's gradient its own.
std::string legend_svg(double scale_mm, double off_part_mm, const std::string& id) {
    const auto& stops = deviation_stops();
    std::string s =
        "<svg class=\"legend\" width=\"250\" height=\"330\" viewBox=\"0 0 250 330\" "
        "role=\"img\"><defs><linearGradient id=\"" +
        id + "\" x1=\"0\" y1=\"1\" x2=\"0\" y2=\"0\">";
    for (std::size_t i = 0; i < stops.size(); ++i)
        s += "<stop offset=\"" +
             fixed(static_cast<double>(i) / static_cast<double>(stops.size() - 1), 2) +
             "\" stop-color=\"" + hex(stops[i]) + "\"/>";
    s += "</linearGradient></defs><text x=\"4\" y=\"14\" font-size=\"13\">deviation, mm</text>"
         "<rect x=\"8\" y=\"28\" width=\"26\" height=\"200\" fill=\"url(#" +
         id + ")\" stroke=\"#444\"/>";
    for (int j = 0; j <= 4; ++j) {
        const double v = scale_mm * (1.0 - 0.5 * j), y = 28 + 50.0 * j;
        std::string text = fixed(v, 2, v != 0);
        if (j == 0) text = "≥ " + text + " excess, flash";
        if (j == 4) text = "≤ " + text + " underfill";
        s += "<line x1=\"34\" y1=\"" + fixed(y, 0) + "\" x2=\"40\" y2=\"" + fixed(y, 0) +
             "\" stroke=\"#444\"/><text x=\"44\" y=\"" + fixed(y + 4, 0) + "\" font-size=\"12\">" +
             text + "</text>";
    }
    const std::pair<Colour, std::string> keys[] = {
        {kOffPartColour, "not the part (support, > " + fixed(off_part_mm, 1) + " mm off)"},
        {kNoPointColour, "no point"},
        {kLevelColour, "measured level (height end)"},
        {kEdgeColour, "measured edge circle (diameter)"}};
    double y = 246;
    for (const auto& [colour, text] : keys) {
        s += "<rect x=\"8\" y=\"" + fixed(y, 0) + "\" width=\"14\" height=\"14\" fill=\"" +
             hex(colour) + "\" stroke=\"#444\"/><text x=\"28\" y=\"" + fixed(y + 12, 0) +
             "\" font-size=\"12\">" + escape(text) + "</text>";
        y += 20;
    }
    return s + "</svg>";
}

// The overlays' labels over the deviation map: an SVG with the picture's pixel coordinates, laid
// over the <img> at the same size, so the names sit on their outlines at any zoom. A label that
// would cover one already placed moves down a line.
std::string labels_svg(const DeviationMap& m, const std::vector<Overlay>& overlays,
                       const std::vector<OverlayPixels>& pixels) {
    const double w = static_cast<double>(m.width), h = static_cast<double>(m.profiles);
    const double font = std::max(8.0, std::max(w, h) / 55);  // about 1/55 of the picture
    std::string s = "<svg class=\"labels\" viewBox=\"0 0 " + std::to_string(m.width) + " " +
                    std::to_string(m.profiles) + "\" role=\"img\">";
    std::vector<Eigen::Vector4d> placed;  // text boxes: x0, y0, x1, y1
    for (std::size_t j = 0; j < overlays.size(); ++j) {
        if (!pixels[j].anchor) continue;
        const Overlay& o = overlays[j];
        const std::string text = o.features + " · " + o.level;
        const double x = static_cast<double>(*pixels[j].anchor % m.width) + 0.5,
                     y = static_cast<double>(*pixels[j].anchor / m.width) + 0.5;
        const double width = 0.6 * font * static_cast<double>(text.size());
        const bool left = x + font / 2 + width > w;  // keep the text inside the picture
        const double x0 = left ? x - font / 2 - width : x + font / 2;
        double baseline = y + font / 3;
        auto overlaps = [&](const Eigen::Vector4d& b) {
            return x0 < b[2] && x0 + width > b[0] && baseline - font < b[3] && baseline > b[1];
        };
        for (int tries = 0; tries < 8 && std::any_of(placed.begin(), placed.end(), overlaps);
             ++tries)
            baseline += 1.2 * font;
        placed.emplace_back(x0, baseline - font, x0 + width, baseline);
        s += "<circle cx=\"" + fixed(x, 1) + "\" cy=\"" + fixed(y, 1) + "\" r=\"" +
             fixed(font / 4, 1) + "\" fill=\"" + hex(o.edge_circle ? kEdgeColour : kLevelColour) +
             "\" stroke=\"#000\"/><text x=\"" + fixed(x0, 1) + "\" y=\"" + fixed(baseline, 1) +
             "\" font-size=\"" + fixed(font, 1) +
             "\" fill=\"#fff\" stroke=\"#000\" stroke-width=\"" + fixed(font / 6, 1) +
             "\" paint-order=\"stroke\">" + escape(text) + "</text>";
    }
    return s + "</svg>";
}

std::string range_figure(const core::FaceScan& face) {
    const RangePicture p = range_picture(face);
    return "<figure class=\"range\"><img alt=\"range image, face " + escape(face.name) +
           "\" src=\"" + png_data_uri(p.image) +
           "\"><figcaption>Range image: one row per profile (scan direction down), one column "
           "per point of the laser line; range " +
           fixed(p.near_mm, 1) + " mm white … " + fixed(p.far_mm, 1) +
           " mm dark grey, black: no return.</figcaption></figure>";
}

// "on the part: 81234 points, median +0.004 mm, 5 % … 95 %: −0.071 … +0.083 mm"
std::string deviation_statistics(const DeviationMap& m) {
    std::vector<float> d;
    for (std::size_t px = 0; px < m.kind.size(); ++px)
        if (m.kind[px] == PixelKind::kPart) d.push_back(m.deviation_mm[px]);
    if (d.empty()) return "no point of the scan on the part";
    auto q = [&](double p) {
        auto at = d.begin() + static_cast<std::ptrdiff_t>(p * static_cast<double>(d.size() - 1));
        std::nth_element(d.begin(), at, d.end());
        return fixed(*at, 3, true);
    };
    return "on the part: " + std::to_string(d.size()) + " points, median " + q(0.5) +
           " mm, 5 % … 95 %: " + q(0.05) + " … " + q(0.95) + " mm";
}

// The deviation map with its overlays and labels, the legend beside it, the overlays listed.
std::string deviation_figure(const DeviationMap& m, const std::vector<Overlay>& overlays,
                             double scale_mm, std::size_t face_index,
                             const PartReportConfig& config) {
    std::vector<OverlayPixels> pixels;
    // Each label in its own direction from its region's centre (the golden angle apart).
    for (std::size_t j = 0; j < overlays.size(); ++j)
        pixels.push_back(overlay_pixels(m, overlays[j], config, 2.39996 * static_cast<double>(j)));
    std::string s =
        "<figure class=\"deviation\"><div class=\"map\"><img alt=\"deviation map, face " +
        escape(m.face) + "\" src=\"" +
        png_data_uri(deviation_picture(m, scale_mm, overlays, pixels)) + "\">" +
        labels_svg(m, overlays, pixels) +
        "</div><figcaption>Deviation from the nominal hot surface (" +
        escape(deviation_statistics(m)) + ").</figcaption></figure>" +
        legend_svg(scale_mm, config.off_part_mm, "deviation-scale-" + std::to_string(face_index));
    s += "</div><ul class=\"overlays\">";
    for (std::size_t j = 0; j < overlays.size(); ++j) {
        const Overlay& o = overlays[j];
        s += "<li><span class=\"swatch\" style=\"background:" +
             hex(o.edge_circle ? kEdgeColour : kLevelColour) + "\"></span>" +
             escape(o.features + ": " + o.what) +
             (o.edge_circle ? ", r " + fixed(o.r_mm, 3) + " mm at z " + fixed(o.z_mm, 3)
                            : ", z " + fixed(o.z_mm, 3)) +
             " mm (hot)" +
             (pixels[j].outline.empty() ? ", no point of this face within its band" : "") + "</li>";
    }
    return s + "</ul>";
}

std::string face_facts(const core::FaceScan& face, const pipeline::PartResult& r) {
    const pipeline::FaceSummary s = pipeline::summarize(face);
    std::string text = std::to_string(s.profiles) + " profiles × " + std::to_string(s.width) +
                       " points, " + std::to_string(s.points) + " with a return; compensation ";
    std::string compensation = "off";
    for (const auto& c : r.compensation)
        if (c.face == face.name)
            compensation =
                c.applied ? "applied (peak " + fixed(c.peak_mm, 3) + " mm)" : "NOT applied";
    return "<p class=\"facts\">" + escape(text + compensation) + "</p>";
}

core::Result<std::string> face_section(const core::FaceScan& face, std::size_t index,
                                       const core::Recipe& recipe, const pipeline::PartResult& r,
                                       const core::AxisymmetricSolid* nominal_hot,
                                       const PartReportConfig& config) {
    std::string s = "<section class=\"face\" id=\"face-" + std::to_string(index) + "\"><h3>Face " +
                    escape(face.name) + "</h3>" + face_facts(face, r);
    if (face.n_profiles() == 0 || face.width == 0)
        return s + "<p>No profiles: no pictures.</p></section>\n";
    s += "<div class=\"pictures\">" + range_figure(face);
    if (!nominal_hot || !r.T_world_part) {
        const std::string why = r.match && !r.match->found ? r.match->reason : "no part pose";
        return s + "</div><p class=\"no-map\">No deviation map: " + escape(why) +
               ".</p></section>\n";
    }
    const auto u = r.displacement_mm.find(face.name);
    if (u != r.displacement_mm.end() &&
        static_cast<std::int64_t>(u->second.size()) != face.n_profiles())
        return core::make_error("part " + r.part_id + ", face " + face.name + ": " +
                                std::to_string(u->second.size()) + " displacements for " +
                                std::to_string(face.n_profiles()) +
                                " profiles: the result is not of this recording");
    const DeviationMap m = deviation_map(face, u != r.displacement_mm.end() ? &u->second : nullptr,
                                         *r.T_world_part, *nominal_hot, config);
    const auto overlays = face_overlays(recipe, r.measurement, face.name, hot_scale(r));
    return s + deviation_figure(m, overlays, colour_scale_mm(recipe), index, config) +
           "</section>\n";
}

std::string summary_table(const pipeline::PartResult& r, double scale) {
    const auto& m = r.measurement;
    std::string s = "<table class=\"summary\">";
    auto row = [&](const std::string& name, const std::string& html) {
        s += "<tr><th>" + name + "</th><td>" + html + "</td></tr>";
    };
    row("verdict", verdict_span(m.verdict) + (r.degraded ? " (degraded)" : ""));
    row("recipe", escape(r.recipe));
    row("captured", escape(r.captured_at));
    row("temperature", m.temperature_c ? fixed(*m.temperature_c, 1) + " °C" : "unknown");
    const std::string why = m.growth                    ? "thermal growth"
                            : r.match && r.match->found ? "estimated by the matching"
                                                        : "no growth known";
    row("nominal surface scale", fixed(scale, 5) + " (" + why + ")");
    std::string pose = r.pose_source.empty() ? "none" : escape(r.pose_source);
    if (r.match)
        pose += r.match->found ? ", score " + fixed(r.match->score, 3) + ", ICP rms " +
                                     fixed(r.match->rms_mm, 3) + " mm"
                               : ": " + escape(r.match->reason);
    row("pose", pose);
    row("compensation", r.compensated ? "on" : "off");
    auto list = [](const std::vector<std::string>& items) {
        std::string l = "<ul>";
        for (const auto& i : items) l += "<li>" + escape(i) + "</li>";
        return l + "</ul>";
    };
    if (!r.degraded_reasons.empty()) row("degraded", list(r.degraded_reasons));
    if (!r.warnings.empty()) row("warnings", list(r.warnings));
    return s + "</table>\n";
}

constexpr const char* kStyle = R"(
body { font-family: sans-serif; margin: 1.5em; color: #222; }
table { border-collapse: collapse; }
th, td { padding: 3px 8px; text-align: left; vertical-align: middle; }
table.features td, table.features th { border-bottom: 1px solid #ddd; }
table.features td.nominal, td.lower, td.upper, td.cold, td.dev, td.u { text-align: right; }
table.summary th { font-weight: normal; color: #555; }
.verdict { font-weight: bold; padding: 1px 6px; border-radius: 3px; color: #fff; }
.v-OK { background: #2e7d32; } .v-NOK { background: #c62828; }
.v-NOT_MEASURED { background: #616161; } .v-DEGRADED { background: #ef6c00; }
.pictures { display: flex; flex-wrap: wrap; gap: 16px; align-items: flex-start; }
figure { margin: 0; flex: 1 1 360px; max-width: calc(50% - 140px); }
td.name, td.cold, td.dev, td.u { white-space: nowrap; }
figure img { display: block; width: 100%; image-rendering: pixelated; }
.map { position: relative; }
.map svg { position: absolute; left: 0; top: 0; width: 100%; height: 100%; }
.swatch { display: inline-block; width: 12px; height: 12px; margin-right: 6px;
          border: 1px solid #444; }
ul.overlays { list-style: none; padding-left: 0; }
)";

}  // namespace

core::Result<std::string> part_report_html(const core::Recording& rec, const core::Recipe& recipe,
                                           const pipeline::PartResult& r,
                                           const PartReportConfig& config) {
    for (const auto& f : r.faces)
        if (!rec.face(f.name))
            return core::make_error("part " + r.part_id + ": face '" + f.name +
                                    "' of the result is not in the recording");
    const double scale = hot_scale(r);
    std::optional<core::AxisymmetricSolid> nominal_hot;
    if (r.T_world_part) nominal_hot = core::AxisymmetricSolid::from_recipe(recipe, {}, {}, scale);
    std::string faces;
    for (std::size_t i = 0; i < rec.faces.size(); ++i) {
        auto section =
            face_section(rec.faces[i], i, recipe, r, nominal_hot ? &*nominal_hot : nullptr, config);
        if (!section) return section.error();
        faces += *section;
    }
    const double scale_mm = colour_scale_mm(recipe);
    return "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>Part " +
           escape(r.part_id) + ": " + measure::to_string(r.measurement.verdict) +
           "</title><style>" + kStyle + "</style></head><body>\n<h1>Part " + escape(r.part_id) +
           "</h1>\n" + summary_table(r, scale) + "<h2>Features</h2>\n" +
           feature_table(r.measurement) +
           "<p>Cold values (20 °C) against the drawing; the band runs from the lower to the upper "
           "limit with the nominal as a tick; a value beyond the drawn range is an arrow at its "
           "edge.</p>\n<h2>Faces</h2>\n<p>Each scan point, compensated for vibration, is taken to "
           "the part frame with the pose above and compared with the nominal surface grown to "
           "the part's temperature: red is material outside the nominal (excess, flash), blue is "
           "missing material (underfill). The scale saturates at ±" +
           fixed(scale_mm, 2) +
           " mm, the largest tolerance of the recipe. Green outlines: the levels the heights were "
           "measured at; yellow: the edge circles of the diameters.</p>\n" +
           faces + "</body></html>\n";
}

}  // namespace hotgauge::report
