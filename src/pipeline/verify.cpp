#include "hotgauge/pipeline/verify.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>

namespace hotgauge::pipeline {

core::Result<Verification> verify(const PartResult& r, const core::MasterCertificate& c) {
    if (r.recipe != c.recipe)
        return core::make_error("the certificate of master " + c.master + " is for recipe '" +
                                c.recipe + "', the part was measured as '" + r.recipe + "'");
    Verification v;
    v.master = c.master;
    v.certified_at = c.certified_at;
    v.passed = true;
    for (const auto& cf : c.features) {
        const measure::FeatureResult* m = nullptr;
        for (const auto& f : r.measurement.features)
            if (f.name == cf.name) m = &f;
        if (!m)
            return core::make_error("certificate of master " + c.master + ": feature '" + cf.name +
                                    "' is not in recipe " + c.recipe);
        FeatureVerification fv;
        fv.name = cf.name;
        fv.certified_mm = cf.value_mm;
        fv.u_certified_mm = cf.u_mm;
        fv.tolerance_mm = cf.tolerance_mm.value_or(c.tolerance_mm);
        fv.measured_mm = m->cold_mm;
        if (!m->cold_mm) {
            fv.reason = "not measured: " + (m->reason.empty() ? "no cold value" : m->reason);
        } else {
            fv.deviation_mm = *m->cold_mm - cf.value_mm;
            fv.passed = std::abs(*fv.deviation_mm) <= fv.tolerance_mm;
            fv.degraded = m->degraded;
            if (fv.degraded) {
                fv.passed = false;
                fv.reason = m->reason;  // "degraded: measured with untrusted profiles; ..."
            } else if (!fv.passed) {
                char buf[96];
                std::snprintf(buf, sizeof buf, "deviation %+.4f mm outside ±%.4f mm",
                              *fv.deviation_mm, fv.tolerance_mm);
                fv.reason = buf;
            }
        }
        v.passed = v.passed && fv.passed;
        v.features.push_back(std::move(fv));
    }
    // Failed only where the value was not there or not trusted (a face left out, an
    // accelerometer gap): the gauge was not shown wrong, the check is to be made again.
    v.inconclusive = !v.passed && std::all_of(v.features.begin(), v.features.end(),
                                              [](const FeatureVerification& f) {
                                                  return f.passed || f.degraded || !f.measured_mm;
                                              });
    return v;
}

std::string to_json(const Verification& v) {
    nlohmann::ordered_json j;
    j["master"] = v.master;
    j["certified_at"] = v.certified_at;
    j["passed"] = v.passed;
    j["inconclusive"] = v.inconclusive;
    j["features"] = nlohmann::ordered_json::array();
    for (const auto& f : v.features) {
        nlohmann::ordered_json o;
        o["name"] = f.name;
        o["certified_mm"] = f.certified_mm;
        o["u_certified_mm"] = f.u_certified_mm;
        o["tolerance_mm"] = f.tolerance_mm;
        o["measured_mm"] = f.measured_mm ? nlohmann::ordered_json(*f.measured_mm) : nullptr;
        o["deviation_mm"] = f.deviation_mm ? nlohmann::ordered_json(*f.deviation_mm) : nullptr;
        o["passed"] = f.passed;
        o["degraded"] = f.degraded;
        o["reason"] = f.reason;
        j["features"].push_back(o);
    }
    return j.dump();
}

std::string to_table(const Verification& v) {
    std::string out = "master " + v.master + " (certified " + v.certified_at +
                      "): " + (v.passed ? "PASSED" : "FAILED") + "\n";
    char line[200];
    std::snprintf(line, sizeof line, "%-16s %11s %11s %10s %9s  %s\n", "feature", "certified",
                  "measured", "deviation", "tolerance", "");
    out += line;
    for (const auto& f : v.features) {
        char meas[32] = "-", dev[32] = "-";
        if (f.measured_mm) std::snprintf(meas, sizeof meas, "%.4f", *f.measured_mm);
        if (f.deviation_mm) std::snprintf(dev, sizeof dev, "%+.4f", *f.deviation_mm);
        std::snprintf(line, sizeof line, "%-16s %11.4f %11s %10s %9.4f  %s\n", f.name.c_str(),
                      f.certified_mm, meas, dev, f.tolerance_mm,
                      f.passed ? "ok" : ("FAIL " + f.reason).c_str());
        out += line;
    }
    return out;
}

}  // namespace hotgauge::pipeline
