#pragma once
// A master part's certificate as plain data (docs/verification.md): a cold part of the recipe
// with certified dimensions, against which the cell is checked.
#include <optional>
#include <string>
#include <vector>

namespace hotgauge::core {

struct CertifiedFeature {
    std::string name;                    // the recipe's feature name
    double value_mm = 0;                 // certified cold value
    double u_mm = 0;                     // its standard uncertainty (the certificate's)
    std::optional<double> tolerance_mm;  // this feature's verification tolerance (±)
};

struct MasterCertificate {
    std::string master;           // the master's serial
    std::string recipe;           // recipe name
    std::string certified_at;     // date of the certificate
    std::string certified_by;     // lab, report
    double temperature_c = 20.0;  // the master's temperature when checked, if not measured
    double tolerance_mm = 0.02;   // default verification tolerance (±)
    std::vector<CertifiedFeature> features;
};

}  // namespace hotgauge::core
