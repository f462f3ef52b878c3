// Fuzzes calib::parse_calibration (config/calibration.yaml, docs/calibration.md). Input: the
// whole file, named fuzz/calibration.yaml. Asserts: no crash, sanitizer report or exception
// (parse_calibration promises a core::Result); an error names the file; an accepted calibration
// has faces with unique names.
#include <set>

#include "fuzz_util.hpp"
#include "hotgauge/calib/calibration.hpp"

using namespace hotgauge;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    static const auto file = fuzz::kDir / "calibration.yaml";
    auto c = fuzz::no_throw("parse_calibration", [&] {
        return calib::parse_calibration(fuzz::text_of(data, size), file);
    });
    if (!c) {
        fuzz::check_error_names(c.error(), file);
        return 0;
    }
    std::set<std::string> names;
    for (const auto& f : c->faces) fuzz::check(names.insert(f.name).second, "face listed twice");
    fuzz::check(!c->faces.empty(), "calibration without faces");
    return 0;
}
