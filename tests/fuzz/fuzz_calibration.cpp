// Fuzzes calib::read_calibration (config/calibration.yaml, docs/calibration.md). Input: the whole
// file. Asserts: no crash, sanitizer report or exception (read_calibration promises a
// core::Result); an error names the file; an accepted calibration has faces with unique names.
#include <set>

#include "fuzz_util.hpp"
#include "hotgauge/calib/calibration.hpp"

using namespace hotgauge;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const auto file = fuzz::input_file("calibration", "calibration.yaml", data, size);
    auto c = fuzz::no_throw("read_calibration", [&] { return calib::read_calibration(file); });
    if (!c) {
        fuzz::check_error_names(c.error(), file);
        return 0;
    }
    std::set<std::string> names;
    for (const auto& f : c->faces) fuzz::check(names.insert(f.name).second, "face listed twice");
    fuzz::check(!c->faces.empty(), "calibration without faces");
    return 0;
}
