// Fuzzes cell::parse_daemon_config (config/hotgauged.yaml, docs/operations.md "Configuration").
// Input: the whole file, named fuzz/hotgauged.yaml, with a file system in which the files the
// seed references exist (only their existence is checked here), so mutations get past them.
// Asserts: no crash, sanitizer report or exception (parse_daemon_config promises a core::Result);
// an error names the file; an accepted config has a recipe and at least one face, listed once.
#include <set>

#include "fuzz_util.hpp"
#include "hotgauge/cell/config.hpp"

using namespace hotgauge;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    static const io::PathExists exists =
        fuzz::files_exist({"calibration.yaml", "parts/hub-a.yaml", "hub-a.hgm", "master.yaml"});
    static const auto file = fuzz::kDir / "hotgauged.yaml";
    auto c = fuzz::no_throw("parse_daemon_config", [&] {
        return cell::parse_daemon_config(fuzz::text_of(data, size), file, exists);
    });
    if (!c) {
        fuzz::check_error_names(c.error(), file);
        return 0;
    }
    fuzz::check(!c->recipes.empty() && !c->faces.empty(), "config without recipes or faces");
    fuzz::check(std::set<std::string>(c->faces.begin(), c->faces.end()).size() == c->faces.size(),
                "a face is listed twice");
    return 0;
}
