#pragma once
// Writing the YAML files hotgauge produces (face.yaml, part.yaml, calibration.yaml): numbers
// that read back as the same double, quoted strings, flow rows, whole-file writes with errors
// naming the file.
#include <filesystem>
#include <string>

#include "hotgauge/core/result.hpp"

namespace hotgauge::io {

// Shortest text that reads back to the same double (std::to_chars round-trip guarantee), with a
// '.' so that YAML 1.1 readers (PyYAML) also see a float: 1 -> "1.0", 1e-05 -> "1.0e-05".
std::string fmt_double(double v);
// A YAML double-quoted scalar (control characters escaped).
std::string quote(const std::string& s);
// n doubles as a flow sequence "[a, b, c]".
std::string fmt_row(const double* v, int n);
// The whole file at once; "PATH: cannot open for writing" / "PATH: write failed".
core::Result<void> write_text(const std::filesystem::path& path, const std::string& text);

}  // namespace hotgauge::io
