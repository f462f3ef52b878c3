#include "hotgauge/report/lot_report.hpp"

#include <algorithm>
#include <cmath>
#include <map>
#include <set>

namespace hotgauge::report {
namespace {

FeatureLot& feature_lot(Lot& lot, const std::string& recipe, const results::FeatureRecord& f) {
    for (FeatureLot& fl : lot.features)
        if (fl.recipe == recipe && fl.name == f.name) return fl;
    FeatureLot fl;
    fl.recipe = recipe;
    fl.name = fl.title = f.name;
    fl.nominal_mm = f.nominal_mm;
    fl.lower_mm = f.lower_mm;
    fl.upper_mm = f.upper_mm;
    lot.features.push_back(std::move(fl));
    return lot.features.back();
}

// Limits, rules, capability and drift of one feature's values.
void add_statistics(FeatureLot& f, const LotOptions& options) {
    constexpr std::size_t kMinBaseline = quality::kMinBaseline;
    if (f.values.size() < kMinBaseline) {
        f.no_statistics = std::to_string(f.values.size()) + " values measured OK or NOK, " +
                          std::to_string(kMinBaseline) + " needed for limits and indices";
        return;
    }
    f.baseline = std::clamp(options.baseline, kMinBaseline, f.values.size());
    const std::span<const double> all(f.values), base = all.first(f.baseline);
    const auto chart = quality::individuals_chart(base);
    const auto cap = quality::capability(all, f.nominal_mm + f.lower_mm, f.nominal_mm + f.upper_mm);
    if (!chart || !cap) {  // values that do not vary, limits in the wrong order
        f.no_statistics = (!chart ? chart.error() : cap.error()).message;
        return;
    }
    f.chart = *chart;
    f.capability = *cap;
    f.violations = quality::western_electric(all, chart->centre, chart->sigma);
    quality::DriftMonitor drift(chart->centre, chart->sigma, {});
    for (std::size_t i = f.baseline; i < f.values.size(); ++i)
        if (const auto d = drift.add(f.values[i]); d != quality::Drift::kNone && !f.drift_at) {
            f.drift_at = i;
            f.first_drift = d;
        }
    f.drift = drift.state();
}

// One study per master, feature and certified value (a recertified master is a new reference).
MasterStudy& master_study(Lot& lot, const std::string& master, const std::string& feature,
                          double certified) {
    for (MasterStudy& m : lot.masters)
        if (m.master == master && m.feature == feature && m.reference_mm == certified) return m;
    lot.masters.push_back({master, feature, certified});
    return lot.masters.back();
}

void add_master_check(Lot& lot, const results::PartRecord& p) {
    ++lot.master_checks;
    for (const auto& [name, certified] : p.certified)
        for (const results::FeatureRecord& f : p.features) {
            if (f.name != name) continue;
            MasterStudy& m = master_study(lot, p.master, name, certified);
            m.tolerance_mm = f.upper_mm - f.lower_mm;
            if (f.usable_mm()) m.values.push_back(*f.cold_mm);
        }
}

void add_study(MasterStudy& m) {
    if (m.values.size() < kMinMasterChecks) {
        m.no_study = std::to_string(m.values.size()) +
                     (m.values.size() == 1 ? " check" : " checks") + " measured OK or NOK, " +
                     std::to_string(kMinMasterChecks) + " needed (VDA 5 asks for 25)";
        return;
    }
    const auto t = quality::type1_study(m.values, m.reference_mm, m.tolerance_mm, 0.0001);
    if (t)
        m.study = *t;
    else
        m.no_study = t.error().message;
}

// The type-3 study of one feature over the parts measured more than once.
RepeatStudy repeat_study(const FeatureLot& f,
                         const std::map<std::string, std::vector<double>>& by_id) {
    RepeatStudy out{f.title, f.upper_mm - f.lower_mm};
    std::map<std::size_t, std::size_t> counts;  // values per part -> parts with that many
    for (const auto& [id, v] : by_id)
        if (v.size() >= 2) ++counts[v.size()];
    std::size_t most = 0;
    for (const auto& [n, parts] : counts)
        if (parts > most) most = parts, out.repeats = n;
    std::vector<std::vector<double>> design;
    for (const auto& [id, v] : by_id)
        if (out.repeats >= 2 && v.size() >= out.repeats)
            design.emplace_back(v.begin(), v.begin() + std::ptrdiff_t(out.repeats));
    out.parts = design.size();
    if (out.parts < kMinRepeatParts) {
        out.no_study = std::to_string(out.parts) + " parts measured " +
                       std::to_string(out.repeats) + " times or more, " +
                       std::to_string(kMinRepeatParts) + " needed";
        return out;
    }
    const auto s = quality::type3_study(design, out.tolerance_mm);
    if (s)
        out.study = *s;
    else
        out.no_study = s.error().message;
    return out;
}

void add_repeat_studies(Lot& lot, const std::vector<results::PartRecord>& parts) {
    std::map<std::string, std::size_t> scans;  // part id -> production results
    for (const auto& p : parts)  // a PLC that sends no part id sends 0: no repeat of one part
        if (!p.master_check && !p.part_id.empty() && p.part_id != "0") ++scans[p.part_id];
    if (std::none_of(scans.begin(), scans.end(), [](const auto& s) { return s.second > 1; }))
        return;
    for (const FeatureLot& f : lot.features) {
        std::map<std::string, std::vector<double>> by_id;
        for (const auto& p : parts) {
            if (p.master_check || p.recipe != f.recipe || scans[p.part_id] < 2) continue;
            for (const auto& r : p.features)
                if (r.name == f.name && r.usable_mm()) by_id[p.part_id].push_back(*r.cold_mm);
        }
        lot.repeats.push_back(repeat_study(f, by_id));
    }
}

}  // namespace

std::string reason_group(const std::string& reason) {
    std::string out = reason.substr(0, reason.find(';'));
    std::set<std::string> causes;
    for (auto at = reason.find("): "); at != std::string::npos; at = reason.find("): ", at + 3)) {
        const auto from = at + 3;
        causes.insert(reason.substr(from, reason.find(';', from) - from));
    }
    std::string joined;
    for (const auto& c : causes) joined += (joined.empty() ? "" : ", ") + c;
    return joined.empty() ? out : out + " (" + joined + ")";
}

Lot summarize_lot(const std::vector<results::PartRecord>& parts, const LotOptions& options) {
    Lot lot;
    for (const results::PartRecord& p : parts) {
        if (p.master_check) {
            add_master_check(lot, p);
            continue;
        }
        if (lot.parts++ == 0) {
            lot.first_time = p.time;
            lot.first_sequence = p.sequence;
        }
        lot.last_time = p.time;
        lot.last_sequence = p.sequence;
        ++lot.verdicts[p.verdict];
        for (const results::FeatureRecord& r : p.features) {
            FeatureLot& f = feature_lot(lot, p.recipe, r);
            ++f.verdicts[r.verdict];
            if (!r.reason.empty()) ++f.reasons[reason_group(r.reason)];
            if (r.usable_mm()) {
                f.values.push_back(*r.cold_mm);
                f.sequences.push_back(p.sequence);
            }
        }
    }
    std::set<std::string> recipes;
    for (const FeatureLot& f : lot.features) recipes.insert(f.recipe);
    for (FeatureLot& f : lot.features) {
        if (recipes.size() > 1) f.title = f.name + " (" + f.recipe + ")";
        add_statistics(f, options);
    }
    for (MasterStudy& m : lot.masters) add_study(m);
    add_repeat_studies(lot, parts);
    return lot;
}

}  // namespace hotgauge::report
