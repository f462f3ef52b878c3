// Fuzzes io::parse_certificate (a master part's certificate, docs/verification.md). Input: the
// whole file, named fuzz/master.yaml. Asserts: no crash, sanitizer report or exception
// (parse_certificate promises a core::Result); an error names the file; an accepted certificate
// has features, uncertainties not negative and tolerances positive.
#include "fuzz_util.hpp"
#include "hotgauge/io/certificate.hpp"

using namespace hotgauge;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    static const auto file = fuzz::kDir / "master.yaml";
    auto c = fuzz::no_throw("parse_certificate",
                            [&] { return io::parse_certificate(fuzz::text_of(data, size), file); });
    if (!c) {
        fuzz::check_error_names(c.error(), file);
        return 0;
    }
    fuzz::check(!c->features.empty() && c->tolerance_mm > 0.0, "certificate invariants");
    for (const auto& f : c->features)
        fuzz::check(f.u_mm >= 0.0 && (!f.tolerance_mm || *f.tolerance_mm > 0.0),
                    "feature invariants");
    return 0;
}
