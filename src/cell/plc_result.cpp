#include "plc_result.hpp"

#include <algorithm>
#include <nlohmann/json.hpp>

namespace hotgauge::cell {

namespace {

plc::Verdict to_plc(measure::Verdict v) {
    switch (v) {
        case measure::Verdict::kOk:
            return plc::Verdict::kOk;
        case measure::Verdict::kNok:
            return plc::Verdict::kNok;
        case measure::Verdict::kDegraded:
            return plc::Verdict::kDegraded;
        case measure::Verdict::kNotMeasured:
            break;
    }
    return plc::Verdict::kNotMeasured;
}

bool failed_check(const std::string& name, const pipeline::Verification* check) {
    if (!check) return false;
    return std::any_of(check->features.begin(), check->features.end(),
                       [&](const auto& v) { return v.name == name && !v.passed; });
}

}  // namespace

std::uint8_t feature_reasons(const measure::FeatureResult& f, const pipeline::Verification* check) {
    namespace why = plc::reason;
    std::uint16_t bits = 0;
    if (!f.cold_mm || f.verdict == measure::Verdict::kNotMeasured) bits |= why::kNotMeasured;
    if (f.verdict == measure::Verdict::kDegraded) bits |= why::kDegraded;
    if (f.deviation_mm && (*f.deviation_mm < f.tol_lower_mm || *f.deviation_mm > f.tol_upper_mm))
        bits |= why::kOutsideTolerance;
    if (f.low_coverage) bits |= why::kLowCoverage;
    if (f.hot_mm && !f.cold_mm) bits |= why::kTemperatureUnknown;
    if (f.face_missing) bits |= why::kFaceMissing;
    if (failed_check(f.name, check)) bits |= why::kMasterCheckFailed;
    return static_cast<std::uint8_t>(bits);
}

// The cold value of each feature (what the tolerance is on); a master check's overall verdict is
// the check's (docs/verification.md).
plc::PartResult to_plc(const pipeline::PartResult& r, const pipeline::Verification* check) {
    plc::PartResult out;
    out.temperature_c = r.measurement.temperature_c;
    for (const auto& f : r.measurement.features) {
        plc::FeatureValue v;
        v.name = f.name;
        v.slot = f.slot;
        v.verdict = to_plc(f.verdict);
        v.required = f.required;
        if (v.verdict != plc::Verdict::kNotMeasured) v.value_mm = f.cold_mm;
        if (!v.value_mm) v.verdict = plc::Verdict::kNotMeasured;
        v.reasons = feature_reasons(f, check);
        out.features.push_back(v);
    }
    if (r.degraded) out.reasons |= plc::reason::kDegraded;
    if (!r.measurement.temperature_c) out.reasons |= plc::reason::kTemperatureUnknown;
    out.overall = plc::overall_verdict(out.features, r.degraded);
    // A master: the check's verdict; inconclusive (failed only on degraded features) reads
    // degraded; a passed check over slots not all OK reads as the slots do.
    if (check && !check->passed)
        out.overall = check->inconclusive ? plc::Verdict::kDegraded : plc::Verdict::kNok;
    else if (check && out.overall != plc::Verdict::kNok)
        out.overall =
            std::all_of(out.features.begin(), out.features.end(),
                        [](const plc::FeatureValue& v) { return v.verdict == plc::Verdict::kOk; })
                ? plc::Verdict::kOk
                : out.overall;
    return out;
}

void set_drift(plc::PartResult& p, const std::vector<std::pair<std::string, std::string>>& drift) {
    for (auto& v : p.features)
        for (const auto& [name, state] : drift)
            if (name == v.name)
                v.drift = state == "DRIFT_UP"     ? plc::DriftState::kUp
                          : state == "DRIFT_DOWN" ? plc::DriftState::kDown
                          : state == "WATCHING"   ? plc::DriftState::kWatching
                                                  : plc::DriftState::kNone;
}

std::string plc_json(const plc::PartResult& p, std::uint16_t fault) {
    nlohmann::json j;
    j["fault"] = fault;
    j["overall"] = static_cast<int>(p.overall);
    j["temperature_c"] = p.temperature_c ? nlohmann::json(*p.temperature_c) : nlohmann::json();
    j["reasons"] = p.reasons;
    j["recipe_revision"] = p.recipe_revision;
    j["features"] = nlohmann::json::array();
    for (const auto& f : p.features)
        j["features"].push_back(
            {{"name", f.name},
             {"slot", f.slot},
             {"value_mm", f.value_mm ? nlohmann::json(*f.value_mm) : nlohmann::json()},
             {"verdict", static_cast<int>(f.verdict)},
             {"required", f.required},
             {"drift", static_cast<int>(f.drift)},
             {"reasons", f.reasons}});
    return j.dump();
}

core::Result<PlcShown> plc_from_json(const std::string& results_line) {
    try {
        const auto line = nlohmann::json::parse(results_line);
        const auto& j = line.at("plc");
        PlcShown out;
        out.fault = j.at("fault").get<std::uint16_t>();
        plc::PartResult& p = out.result;
        p.overall = static_cast<plc::Verdict>(j.at("overall").get<std::uint16_t>());
        if (j.at("temperature_c").is_number()) p.temperature_c = j["temperature_c"].get<double>();
        p.reasons = j.at("reasons").get<std::uint16_t>();
        p.recipe_revision = j.at("recipe_revision").get<std::uint16_t>();
        p.sequence = line.at("sequence").get<std::uint64_t>();
        p.time_ns = line.at("time_ns").get<std::int64_t>();
        for (const auto& f : j.at("features")) {
            plc::FeatureValue v;
            v.name = f.at("name").get<std::string>();
            v.slot = f.at("slot").get<int>();
            if (f.at("value_mm").is_number()) v.value_mm = f["value_mm"].get<double>();
            v.verdict = static_cast<plc::Verdict>(f.at("verdict").get<std::uint16_t>());
            v.required = f.at("required").get<bool>();
            v.drift = static_cast<plc::DriftState>(f.at("drift").get<std::uint16_t>());
            v.reasons = f.at("reasons").get<std::uint8_t>();
            p.features.push_back(std::move(v));
        }
        if (auto ok = plc::check_result(p); !out.fault && !ok) return ok.error();
        return out;
    } catch (const nlohmann::json::exception& e) {
        return core::make_error(std::string("the results line's \"plc\": ") + e.what());
    }
}

std::string verdict_text(const pipeline::PartResult& r, const pipeline::Verification* check) {
    const plc::PartResult p = to_plc(r, check);
    return plc::to_string(p.overall);
}

}  // namespace hotgauge::cell
