#pragma once
// The master-part check (docs/verification.md): a part result of the master against its
// certificate, feature by feature, pass or fail against the verification tolerance.
#include <optional>
#include <string>
#include <vector>

#include "hotgauge/core/master.hpp"
#include "hotgauge/core/result.hpp"
#include "hotgauge/pipeline/pipeline.hpp"

namespace hotgauge::pipeline {

struct FeatureVerification {
    std::string name;
    double certified_mm = 0, u_certified_mm = 0, tolerance_mm = 0;
    std::optional<double> measured_mm;   // cold; absent = not measured
    std::optional<double> deviation_mm;  // measured − certified
    bool passed = false;
    bool degraded = false;  // measured only with untrusted profiles: not checked, fails
    std::string reason;     // why it failed
};

struct Verification {
    std::string master, certified_at;
    bool passed = false;  // every certified feature measured, trusted and within its tolerance
    // Failed only because certified features were degraded: the check could not be made on
    // trusted data (the PLC reads degraded, not NOK).
    bool inconclusive = false;
    std::vector<FeatureVerification> features;  // in certificate order
};

// A certified feature the recipe does not have is an error (a certificate of another recipe);
// one not measured fails with the measurement's reason.
core::Result<Verification> verify(const PartResult& result,
                                  const core::MasterCertificate& certificate);

std::string to_json(const Verification& v);
std::string to_table(const Verification& v);

}  // namespace hotgauge::pipeline
