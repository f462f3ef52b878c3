// Fuzzes cell::read_daemon_config (config/hotgauged.yaml, docs/operations.md "Configuration").
// Input: the whole file, read as <scratch>/hotgauged.yaml. The files the seed references exist
// beside it (empty: only their existence is checked here), so mutations get past them.
// Asserts: no crash, sanitizer report or exception (read_daemon_config promises a core::Result);
// an error names the file; an accepted config has a recipe and at least one face, listed once.
#include <set>

#include "fuzz_util.hpp"
#include "hotgauge/cell/config.hpp"

using namespace hotgauge;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    static const bool referenced = [] {
        std::filesystem::create_directories(fuzz::scratch_dir("daemon_config") / "parts");
        for (const char* f : {"calibration.yaml", "parts/hub-a.yaml", "hub-a.hgm", "master.yaml"})
            fuzz::input_file("daemon_config", f, nullptr, 0);
        return true;
    }();
    (void)referenced;
    const auto file = fuzz::input_file("daemon_config", "hotgauged.yaml", data, size);
    auto c = fuzz::no_throw("read_daemon_config", [&] { return cell::read_daemon_config(file); });
    if (!c) {
        fuzz::check_error_names(c.error(), file);
        return 0;
    }
    fuzz::check(!c->recipes.empty() && !c->faces.empty(), "config without recipes or faces");
    fuzz::check(std::set<std::string>(c->faces.begin(), c->faces.end()).size() == c->faces.size(),
                "a face is listed twice");
    return 0;
}
