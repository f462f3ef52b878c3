#pragma once
// Reading a master part's certificate (docs/verification.md "Certificate").
#include <filesystem>

#include "hotgauge/core/master.hpp"
#include "hotgauge/core/result.hpp"
#include "hotgauge/io/bytes.hpp"

namespace hotgauge::io {

// Strict: format hotgauge-master-1, every key known, feature names unique, tolerances positive,
// uncertainties not negative. Errors name file:line and the key.
core::Result<core::MasterCertificate> read_certificate(const std::filesystem::path& file);
// The same on the file's text, `file` naming it in errors.
core::Result<core::MasterCertificate> parse_certificate(std::string_view text,
                                                        const std::filesystem::path& file);

}  // namespace hotgauge::io
