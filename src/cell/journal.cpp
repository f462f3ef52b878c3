#include "hotgauge/cell/journal.hpp"

#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/sinks/systemd_sink.h>
#include <spdlog/spdlog.h>
#include <sys/stat.h>
#include <systemd/sd-journal.h>

#include <cstdio>
#include <cstdlib>

namespace hotgauge::cell {

bool stderr_is_journal() {
    const char* env = std::getenv("JOURNAL_STREAM");
    if (!env) return false;
    unsigned long long dev = 0, ino = 0;
    if (std::sscanf(env, "%llu:%llu", &dev, &ino) != 2) return false;
    struct stat st {};
    if (::fstat(2, &st) != 0) return false;
    return st.st_dev == dev && st.st_ino == ino;
}

void init_logging(const std::string& identifier) {
    std::shared_ptr<spdlog::logger> logger;
    if (stderr_is_journal()) {
        auto sink = std::make_shared<spdlog::sinks::systemd_sink_mt>(identifier);
        logger = std::make_shared<spdlog::logger>(identifier, sink);
    } else {
        logger = spdlog::stderr_color_mt(identifier);
    }
    spdlog::set_default_logger(logger);
}

std::string verdict_field(bool fault, plc::Verdict published) {
    if (fault) return "FAULT";
    switch (published) {
        case plc::Verdict::kOk:
            return "OK";
        case plc::Verdict::kNok:
            return "NOK";
        case plc::Verdict::kNotMeasured:
            return "NOT_MEASURED";
        case plc::Verdict::kDegraded:
            return "DEGRADED";
        case plc::Verdict::kNone:
            break;
    }
    return "NONE";
}

void log_part(const PartRecord& r) {
    if (stderr_is_journal()) {
        sd_journal_send("MESSAGE=%s", r.message.c_str(), "PRIORITY=%d", r.problem ? 4 : 6,
                        "SEQ=%llu", static_cast<unsigned long long>(r.sequence), "PART_ID=%s",
                        r.part_id.c_str(), "RECIPE=%s", r.recipe.c_str(), "VERDICT=%s",
                        r.verdict.c_str(), "SYSLOG_IDENTIFIER=hotgauged", nullptr);
        return;
    }
    if (r.problem)
        spdlog::warn("{}", r.message);
    else
        spdlog::info("{}", r.message);
}

}  // namespace hotgauge::cell
