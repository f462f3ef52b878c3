// How the results files write times (declared in results_log.hpp): the local time with its
// offset and the UTC time of a part in its CSV row and JSON line, and the local date that names
// the day's files and archive folders.
#include <cstdio>
#include <ctime>
#include <string>

#include "hotgauge/results/results_log.hpp"

namespace hotgauge::results {
namespace {

std::tm local_tm(std::int64_t time_ns) {
    const std::time_t secs = static_cast<std::time_t>(time_ns / 1'000'000'000);
    std::tm tm{};
    localtime_r(&secs, &tm);
    return tm;
}

}  // namespace

std::string local_iso8601(std::int64_t time_ns) {
    const std::tm tm = local_tm(time_ns);
    char date[32], zone[8];
    std::strftime(date, sizeof date, "%Y-%m-%dT%H:%M:%S", &tm);
    std::strftime(zone, sizeof zone, "%z", &tm);  // +0100
    const std::string z(zone);
    const long ms = static_cast<long>((time_ns / 1'000'000) % 1000);
    char out[64];
    std::snprintf(out, sizeof out, "%s.%03ld%s:%s", date, ms, z.substr(0, 3).c_str(),
                  z.substr(3).c_str());
    return out;
}

std::string local_date(std::int64_t time_ns) {
    const std::tm tm = local_tm(time_ns);
    char date[16];
    std::strftime(date, sizeof date, "%Y-%m-%d", &tm);
    return date;
}

std::string utc_iso8601(std::int64_t time_ns) {
    const std::time_t secs = static_cast<std::time_t>(time_ns / 1'000'000'000);
    std::tm tm{};
    gmtime_r(&secs, &tm);
    char date[32], out[48];
    std::strftime(date, sizeof date, "%Y-%m-%dT%H:%M:%S", &tm);
    std::snprintf(out, sizeof out, "%s.%03ldZ", date,
                  static_cast<long>((time_ns / 1'000'000) % 1000));
    return out;
}

}  // namespace hotgauge::results
