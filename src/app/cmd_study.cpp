// hotgauge study type1|type3 RESULTS: the gauge studies of docs/quality.md on one feature's
// values read back from a results folder (docs/results.md).
#include <cstdio>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "commands.hpp"
#include "hotgauge/quality/statistics.hpp"
#include "hotgauge/results/read_back.hpp"

namespace hotgauge::app {
namespace {

struct StudyArgs {
    std::string results, feature, part_id;
    double reference = 0, tolerance = 0, resolution = 0.0001;
    bool json = false;
};

// The feature's measured values (of one part id when given); prints what was left out.
core::Result<std::vector<results::FeatureValue>> measured(const StudyArgs& a) {
    auto series = results::read_feature_values(a.results, a.feature);
    if (!series) return series.error();
    std::vector<results::FeatureValue> out;
    std::size_t not_measured = 0;
    for (auto& v : series->values) {
        if (!a.part_id.empty() && v.part_id != a.part_id) continue;
        if (v.cold_mm)
            out.push_back(std::move(v));
        else
            ++not_measured;
    }
    std::fprintf(stderr, "%s: %zu results in %zu files; '%s': %zu measured, %zu not measured\n",
                 a.results.c_str(), series->lines, series->files, a.feature.c_str(), out.size(),
                 not_measured);
    return out;
}

int fail(const std::string& why) {
    std::fprintf(stderr, "hotgauge study: %s\n", why.c_str());
    return 1;
}

int run_type1(const StudyArgs& a) {
    const auto values = measured(a);
    if (!values) return fail(values.error().message);
    std::vector<double> x;
    for (const auto& v : *values) x.push_back(*v.cold_mm);
    const auto t = quality::type1_study(x, a.reference, a.tolerance, a.resolution);
    if (!t) return fail(a.feature + ": " + t.error().message);
    if (a.json) {
        const nlohmann::json j = {
            {"feature", a.feature},  {"n", t->n},
            {"mean_mm", t->mean},    {"s_mm", t->s},
            {"bias_mm", t->bias},    {"cg", t->cg},
            {"cgk", t->cgk},         {"t", t->t},
            {"p_value", t->p_value}, {"resolution_share", t->resolution_share}};
        std::printf("%s\n", j.dump().c_str());
        return 0;
    }
    std::printf(
        "type-1 study, %s: n %zu, mean %.5f mm, s %.5f mm, bias %+.5f mm (t %.2f, p %.3g)\n"
        "Cg %.2f, Cgk %.2f, resolution %.1f %% of the tolerance\n",
        a.feature.c_str(), t->n, t->mean, t->s, t->bias, t->t, t->p_value, t->cg, t->cgk,
        100 * t->resolution_share);
    return 0;
}

int run_type3(const StudyArgs& a) {
    const auto values = measured(a);
    if (!values) return fail(values.error().message);
    std::map<std::string, std::vector<double>> by_id;  // part id → its repeats, in order
    for (const auto& v : *values) by_id[v.part_id].push_back(*v.cold_mm);
    std::vector<std::vector<double>> parts;
    for (auto& [id, x] : by_id) parts.push_back(std::move(x));
    const auto s = quality::type3_study(parts, a.tolerance);
    if (!s) return fail(a.feature + ": " + s.error().message);
    if (a.json) {
        const nlohmann::json j = {{"feature", a.feature},
                                  {"parts", s->parts},
                                  {"repeats", s->repeats},
                                  {"ms_parts", s->ms_parts},
                                  {"ms_within", s->ms_within},
                                  {"grr_mm", s->grr},
                                  {"pv_mm", s->pv},
                                  {"tv_mm", s->tv},
                                  {"grr_percent_tv", s->grr_percent_tv},
                                  {"grr_percent_tolerance", s->grr_percent_tolerance},
                                  {"ndc", s->ndc}};
        std::printf("%s\n", j.dump().c_str());
        return 0;
    }
    std::printf(
        "type-3 study, %s: %zu parts x %zu repeats; GRR %.5f mm, PV %.5f mm; %%GRR %.1f %% "
        "of TV, %.1f %% of the tolerance; ndc %d\n",
        a.feature.c_str(), s->parts, s->repeats, s->grr, s->pv, s->grr_percent_tv,
        s->grr_percent_tolerance, s->ndc);
    return 0;
}

}  // namespace

Command add_study(CLI::App& app) {
    auto a = std::make_shared<StudyArgs>();
    auto* s = app.add_subcommand("study", "gauge studies on a results folder (docs/quality.md)");
    s->require_subcommand(1);
    auto common = [&](CLI::App* c) {
        c->add_option("results", a->results, "results folder (YYYY-MM-DD.jsonl files)")->required();
        c->add_option("--feature", a->feature, "feature name, as in the recipe")->required();
        c->add_option("--tolerance", a->tolerance, "tolerance width T (upper - lower), mm")
            ->required();
        c->add_flag("--json", a->json, "print one JSON object");
    };
    auto* t1 = s->add_subcommand("type1", "type-1 study: one reference part measured repeatedly");
    common(t1);
    t1->add_option("--reference", a->reference, "the reference part's certified value, mm")
        ->required();
    t1->add_option("--resolution", a->resolution, "the value's resolution, mm")
        ->capture_default_str();
    t1->add_option("--part-id", a->part_id, "only the results of this part id");
    auto* t3 = s->add_subcommand("type3", "type-3 study: n parts (part ids) x r repeats each");
    common(t3);
    return [a, t1] { return t1->parsed() ? run_type1(*a) : run_type3(*a); };
}

}  // namespace hotgauge::app
