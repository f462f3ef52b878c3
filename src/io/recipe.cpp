#include "hotgauge/io/recipe.hpp"

#include <algorithm>
#include <cmath>
#include <map>
#include <set>

#include "hotgauge/io/yaml_reader.hpp"

namespace hotgauge::io {
namespace {

using core::FeatureKind;
using core::FeatureSpec;
using core::Recipe;
using core::Section;

// How closely a feature's nominal must agree with the recipe geometry: a typo guard.
constexpr double kNominalCheckMm = 1e-3;

std::vector<Section> read_sections(const YamlReader& y, const YAML::Node& list,
                                   const std::string& what, const Recipe& r) {
    if (!list.IsSequence()) y.fail(list, what + ": expected a list of sections");
    std::vector<Section> out;
    for (std::size_t i = 0; i < list.size(); ++i) {
        const YAML::Node n = list[i];
        const std::string w = what + "[" + std::to_string(i) + "]";
        y.expect_map(n, w, {"name", "from", "to", "diameter_mm"});
        Section s;
        s.name = y.string(y.require(n, w, "name"), w + ".name");
        s.from_level = y.string(y.require(n, w, "from"), w + ".from");
        s.to_level = y.string(y.require(n, w, "to"), w + ".to");
        s.diameter_mm = y.number(y.require(n, w, "diameter_mm"), w + ".diameter_mm");
        for (const auto& l : {s.from_level, s.to_level})
            if (!r.level(l))
                y.fail(n, w + ": unknown level '" + l + "' (not in geometry.levels_mm)");
        if (*r.level(s.from_level) >= *r.level(s.to_level))
            y.fail(n, w + ": level '" + s.from_level + "' must lie below '" + s.to_level + "'");
        if (s.diameter_mm <= 0.0) y.fail(n, w + ".diameter_mm: must be positive");
        const bool listed =
            std::any_of(out.begin(), out.end(), [&](const Section& o) { return o.name == s.name; });
        if (listed || r.section(s.name)) y.fail(n, w + ": duplicate section name '" + s.name + "'");
        out.push_back(s);
    }
    return out;
}

FeatureSpec read_feature(const YamlReader& y, const YAML::Node& n, const std::string& w,
                         const Recipe& r) {
    y.expect_map(n, w,
                 {"name", "slot", "kind", "faces", "section", "edge_at", "from", "to", "method",
                  "nominal_mm", "tolerance_mm", "required"});
    FeatureSpec f;
    if (n["required"]) f.required = y.boolean(n["required"], w + ".required");
    f.name = y.string(y.require(n, w, "name"), w + ".name");
    const std::int64_t slot = y.integer(y.require(n, w, "slot"), w + ".slot");
    if (slot < 1 || slot > 1000) y.fail(n["slot"], w + ".slot: must be in 1..1000");
    f.slot = static_cast<int>(slot);
    f.faces = y.strings(y.require(n, w, "faces"), w + ".faces");
    f.nominal_mm = y.number(y.require(n, w, "nominal_mm"), w + ".nominal_mm");
    const auto tol = y.numbers(y.require(n, w, "tolerance_mm"), w + ".tolerance_mm", 2);
    f.tol_lower_mm = tol[0];
    f.tol_upper_mm = tol[1];
    if (f.tol_lower_mm > 0.0 || f.tol_upper_mm < 0.0)
        y.fail(n["tolerance_mm"], w + ".tolerance_mm: expected [lower <= 0, upper >= 0]");
    const std::string kind = y.string(y.require(n, w, "kind"), w + ".kind");
    auto level = [&](const char* key) {
        const std::string l = y.string(y.require(n, w, key), w + "." + key);
        if (!r.level(l)) y.fail(n[key], w + "." + key + ": unknown level '" + l + "'");
        return l;
    };
    double expected = 0.0;
    if (kind == "diameter") {
        f.kind = FeatureKind::kDiameter;
        f.section = y.string(y.require(n, w, "section"), w + ".section");
        const Section* s = r.section(f.section);
        if (!s) y.fail(n["section"], w + ".section: unknown section '" + f.section + "'");
        f.edge_at = level("edge_at");
        if (f.edge_at != s->from_level && f.edge_at != s->to_level)
            y.fail(n["edge_at"], w + ".edge_at: '" + f.edge_at + "' is not an end of section '" +
                                     f.section + "' (" + s->from_level + ", " + s->to_level + ")");
        for (const char* k : {"from", "to", "method"})
            if (n[k]) y.fail(n[k], w + "." + k + ": not used by a diameter feature");
        expected = s->diameter_mm;
    } else if (kind == "height") {
        f.kind = FeatureKind::kHeight;
        f.from_level = level("from");
        f.to_level = level("to");
        const std::string method = n["method"] ? y.string(n["method"], w + ".method") : "planes";
        if (method == "planes")
            f.height_method = core::HeightMethod::kPlanes;
        else if (method == "edges")
            f.height_method = core::HeightMethod::kEdges;
        else
            y.fail(n["method"],
                   w + ".method: expected 'planes' or 'edges', found '" + method + "'");
        for (const char* k : {"section", "edge_at"})
            if (n[k]) y.fail(n[k], w + "." + k + ": not used by a height feature");
        expected = std::abs(*r.level(f.to_level) - *r.level(f.from_level));
    } else if (kind == "die_shift") {
        f.kind = FeatureKind::kDieShift;
        if (!r.forging)
            y.fail(n["kind"], w + ".kind: a die_shift feature needs the recipe's 'forging' "
                                  "drawing (its parting plane)");
        for (const char* k : {"section", "edge_at", "from", "to", "method"})
            if (n[k]) y.fail(n[k], w + "." + k + ": not used by a die_shift feature");
        if (f.tol_lower_mm != 0.0)
            y.fail(n["tolerance_mm"], w + ".tolerance_mm: a die shift is a distance, its lower "
                                          "tolerance is 0");
    } else {
        y.fail(n["kind"],
               w + ".kind: expected 'diameter', 'height' or 'die_shift', found '" + kind + "'");
    }
    if (std::abs(expected - f.nominal_mm) > kNominalCheckMm)
        y.fail(n["nominal_mm"], w + ".nominal_mm: " + std::to_string(f.nominal_mm) +
                                    " disagrees with the geometry (" + std::to_string(expected) +
                                    ")");
    return f;
}

// A mapping of names (sections or levels) to a non-negative number at most `max`.
std::map<std::string, double> read_named(const YamlReader& y, const YAML::Node& m,
                                         const std::string& what, double max, bool level,
                                         const Recipe& r) {
    if (!m.IsMap()) y.fail(m, what + ": expected a mapping of name to value");
    std::map<std::string, double> out;
    for (const auto& kv : m) {
        const auto name = kv.first.as<std::string>();
        const std::string w = what + "." + name;
        if (level ? !r.level(name) : !r.section(name))
            y.fail(kv.first, w + ": unknown " + (level ? "level" : "section") + " '" + name + "'");
        const double v = y.number(kv.second, w);
        if (!(v >= 0.0 && v <= max))
            y.fail(kv.second, w + ": expected 0 .. " + std::to_string(max));
        out[name] = v;
    }
    return out;
}

// The forging drawing's notes: parting plane, draft, fillets, die shift (docs/recipes.md).
core::ForgingSpec read_forging(const YamlReader& y, const YAML::Node& m, const Recipe& r) {
    y.expect_map(m, "forging",
                 {"parting_z_mm", "draft_deg", "fillet_mm", "die_shift_mm", "section_draft_deg",
                  "level_fillet_mm"});
    core::ForgingSpec f;
    f.parting_z_mm = y.number(y.require(m, "forging", "parting_z_mm"), "forging.parting_z_mm");
    double z_lo = 1e300, z_hi = -1e300;
    for (const auto& [name, z] : r.levels_mm) {
        z_lo = std::min(z_lo, z);
        z_hi = std::max(z_hi, z);
    }
    if (!(f.parting_z_mm > z_lo && f.parting_z_mm < z_hi))
        y.fail(m["parting_z_mm"], "forging.parting_z_mm: must lie inside the part (" +
                                      std::to_string(z_lo) + " .. " + std::to_string(z_hi) + ")");
    auto bounded = [&](const char* key, double max) {
        const double v = y.number_or(m, "forging", key, 0.0);
        if (!(v >= 0.0 && v <= max))
            y.fail(m[key],
                   std::string("forging.") + key + ": expected 0 .. " + std::to_string(max));
        return v;
    };
    f.draft_deg = bounded("draft_deg", 10.0);
    f.fillet_mm = bounded("fillet_mm", 20.0);
    f.die_shift_mm = bounded("die_shift_mm", 5.0);
    if (m["section_draft_deg"])
        f.section_draft_deg =
            read_named(y, m["section_draft_deg"], "forging.section_draft_deg", 10.0, false, r);
    if (m["level_fillet_mm"])
        f.level_fillet_mm =
            read_named(y, m["level_fillet_mm"], "forging.level_fillet_mm", 20.0, true, r);
    return f;
}

}  // namespace

core::Result<Recipe> parse_recipe(std::string_view text, const std::filesystem::path& file,
                                  const PathExists& exists) {
    const YamlReader y(file.string(), text, exists);
    return y.guarded<Recipe>([&] {
        const YAML::Node root = y.load();
        y.expect_map(
            root, "recipe",
            {"part", "description", "geometry", "material", "matching", "forging", "features"});
        Recipe r;
        r.source = file.string();
        r.name = y.string(y.require(root, "recipe", "part"), "part");

        const YAML::Node g = y.require(root, "recipe", "geometry");
        y.expect_map(g, "geometry", {"kind", "levels_mm", "outer", "inner", "mesh_file"});
        if (g["mesh_file"]) {
            // Relative to the recipe's folder; the surface model for matching (PLY or STL).
            std::filesystem::path mesh = y.string(g["mesh_file"], "geometry.mesh_file");
            if (mesh.is_relative()) mesh = file.parent_path() / mesh;
            const auto ext = mesh.extension().string();
            if (ext != ".ply" && ext != ".stl" && ext != ".PLY" && ext != ".STL")
                y.fail(g["mesh_file"], "geometry.mesh_file: expected a .ply or .stl file");
            r.mesh_file = y.existing(g["mesh_file"], "geometry.mesh_file", mesh).string();
        }
        const std::string kind = y.string(y.require(g, "geometry", "kind"), "geometry.kind");
        if (kind != "axisymmetric")
            y.fail(g["kind"], "geometry.kind: expected 'axisymmetric', found '" + kind + "'");
        const YAML::Node levels = y.require(g, "geometry", "levels_mm");
        if (!levels.IsMap() || levels.size() == 0)
            y.fail(levels, "geometry.levels_mm: expected a mapping of level name to z (mm)");
        for (const auto& kv : levels) {
            const auto name = kv.first.as<std::string>();
            r.levels_mm.emplace_back(name, y.number(kv.second, "geometry.levels_mm." + name));
        }
        r.outer = read_sections(y, y.require(g, "geometry", "outer"), "geometry.outer", r);
        if (g["inner"]) r.inner = read_sections(y, g["inner"], "geometry.inner", r);

        if (const YAML::Node m = root["material"]) {
            y.expect_map(m, "material", {"alpha0_per_k", "alpha1_per_k2"});
            r.material.alpha0_per_k =
                y.number(y.require(m, "material", "alpha0_per_k"), "material.alpha0_per_k");
            r.material.alpha1_per_k2 = y.number_or(m, "material", "alpha1_per_k2", 0.0);
            // Metals expand by well under 5 % up to 1600 °C; anything else is a typo.
            for (double t : {-50.0, 1600.0}) {
                const double growth = r.material.growth(t);
                if (!(growth > 0.95 && growth < 1.05))
                    y.fail(m, "material: alpha gives growth " + std::to_string(growth) + " at " +
                                  std::to_string(static_cast<int>(t)) + " °C, outside 0.95..1.05");
            }
        } else {
            y.fail(root, "recipe: missing key 'material' (the thermal model is required)");
        }

        if (const YAML::Node m = root["matching"]) {
            y.expect_map(m, "matching", {"sampling_mm", "min_score", "score_band_mm"});
            r.matching.sampling_mm = y.number_or(m, "matching", "sampling_mm", 5.0);
            r.matching.min_score = y.number_or(m, "matching", "min_score", 0.8);
            if (!(r.matching.sampling_mm >= 0.5 && r.matching.sampling_mm <= 50.0))
                y.fail(m["sampling_mm"], "matching.sampling_mm: expected 0.5 .. 50 mm");
            r.matching.score_band_mm = y.number_or(m, "matching", "score_band_mm", 0.0);
            if (!(r.matching.score_band_mm >= 0.0 && r.matching.score_band_mm <= 5.0))
                y.fail(m["score_band_mm"], "matching.score_band_mm: expected 0 .. 5 mm");
            if (!(r.matching.min_score > 0.0 && r.matching.min_score < 1.0))
                y.fail(m["min_score"], "matching.min_score: expected a fraction in (0, 1)");
        }

        if (const YAML::Node m = root["forging"]) r.forging = read_forging(y, m, r);

        const YAML::Node fl = y.require(root, "recipe", "features");
        if (!fl.IsSequence()) y.fail(fl, "features: expected a list");
        std::set<std::string> names;
        std::map<int, std::string> slots;  // slot: the feature on it
        for (std::size_t i = 0; i < fl.size(); ++i) {
            const std::string w = "features[" + std::to_string(i) + "]";
            FeatureSpec f = read_feature(y, fl[i], w, r);
            if (!names.insert(f.name).second)
                y.fail(fl[i], w + ".name: duplicate feature name '" + f.name + "'");
            if (auto [it, fresh] = slots.emplace(f.slot, f.name); !fresh)
                y.fail(fl[i]["slot"], w + ".slot: feature '" + f.name + "' on slot " +
                                          std::to_string(f.slot) + ", which feature '" +
                                          it->second + "' has already");
            r.features.push_back(std::move(f));
        }
        return r;
    });
}

core::Result<Recipe> read_recipe(const std::filesystem::path& file) {
    return parse_file(file, [](std::string_view text, const std::filesystem::path& f) {
        return parse_recipe(text, f);
    });
}

}  // namespace hotgauge::io
