// hotgauge verify: the master-part check (docs/verification.md). The master's recording is
// measured as `hotgauge measure` would, then compared with its certificate. Exit 0 passed,
// 3 failed, 1 error.
#include <spdlog/spdlog.h>

#include <cstdio>
#include <memory>

#include "commands.hpp"
#include "hotgauge/io/certificate.hpp"
#include "hotgauge/pipeline/verify.hpp"

namespace hotgauge::app {
namespace {

struct VerifyArgs {
    MeasureJob job;
    std::string certificate;
    bool json = false;
};

int run(VerifyArgs a) {
    auto cert = io::read_certificate(a.certificate);
    if (!cert) {
        spdlog::error("{}", cert.error().message);
        return 1;
    }
    a.job.default_temperature_c = cert->temperature_c;  // a cold master: no pyrometer reading
    const auto result = measure_job(a.job);
    if (!result) return 1;
    auto v = pipeline::verify(*result, *cert);
    if (!v) {
        spdlog::error("{}", v.error().message);
        return 1;
    }
    if (a.json)
        std::printf("%s\n", pipeline::to_json(*v).c_str());
    else
        std::fputs(pipeline::to_table(*v).c_str(), stdout);
    return v->passed ? 0 : 3;
}

}  // namespace

Command add_verify(CLI::App& app) {
    auto a = std::make_shared<VerifyArgs>();
    auto* s = app.add_subcommand(
        "verify", "check the cell on a master part: its recording against its certificate");
    s->add_option("--master", a->certificate, "the master's certificate (hotgauge-master-1)")
        ->required();
    add_measure_job_options(s, a->job);
    s->add_flag("--json", a->json, "print one JSON object (docs/verification.md)");
    return [a] { return run(*a); };
}

}  // namespace hotgauge::app
