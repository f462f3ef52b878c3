// hotgauge report part: one part's report (docs/results.md "Part report"), from a recording, or
// from the recording the daemon archived for a sequence number of a results folder.
#include <spdlog/spdlog.h>

#include <cctype>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>

#include "commands.hpp"
#include "hotgauge/report/part_report.hpp"
#include "hotgauge/results/read_back.hpp"

namespace hotgauge::app {
namespace {

namespace fs = std::filesystem;

struct ReportPartArgs {
    MeasureJob job;
    std::string results;
    std::optional<std::uint64_t> sequence;
    std::string out;
};

// The part id as a file name: letters, digits, '-', '_' and '.' kept, anything else '_'.
std::string file_name_of(const std::string& part_id) {
    std::string s = part_id.empty() ? "unknown" : part_id;
    for (char& c : s)
        if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '_' && c != '.')
            c = '_';
    return "part-" + s + ".html";
}

core::Result<void> write_file(const fs::path& path, const std::string& text) {
    std::error_code ec;
    fs::create_directories(path.parent_path(), ec);
    if (ec)
        return core::make_error(path.parent_path().string() +
                                ": cannot create the report folder: " + ec.message());
    std::ofstream out(path, std::ios::binary);
    out << text;
    out.close();
    if (!out) return core::make_error(path.string() + ": cannot write");
    return {};
}

int run(ReportPartArgs a) {
    if (!a.results.empty() || a.sequence) {
        if (a.results.empty() || !a.sequence || !a.job.recording.empty()) {
            spdlog::error("report part: give a RECORDING, or --results DIR with --sequence N");
            return 2;
        }
        auto folder = results::archived_recording(a.results, *a.sequence);
        if (!folder) {
            spdlog::error("{}", folder.error().message);
            return 1;
        }
        a.job.recording = folder->string();
    } else if (a.job.recording.empty()) {
        spdlog::error("report part: give a RECORDING, or --results DIR with --sequence N");
        return 2;
    }
    core::Recording rec;
    core::Recipe recipe;
    const auto result = measure_job(a.job, &rec, &recipe);
    if (!result) return 1;
    const auto html = report::part_report_html(rec, recipe, *result);
    const fs::path path = fs::path(a.out) / file_name_of(result->part_id);
    auto written = html ? write_file(path, *html) : core::Result<void>(html.error());
    if (!written) {
        spdlog::error("{}", written.error().message);
        return 1;
    }
    std::printf("%s\n", path.string().c_str());
    return 0;
}

}  // namespace

Command add_report_part(CLI::App* report) {
    auto a = std::make_shared<ReportPartArgs>();
    auto* s = report->add_subcommand(
        "part", "one part's report: range images, deviation maps, features on their bands");
    add_measure_job_options(s, a->job);
    s->get_option("recording")->required(false);  // or --results with --sequence
    s->add_option("--results", a->results,
                  "results folder: report the part the daemon archived for --sequence");
    s->add_option("--sequence", a->sequence, "the part's sequence number in --results");
    s->add_option("--out", a->out, "folder the report is written to (part-<part id>.html)")
        ->required();
    return [a] { return run(*a); };
}

}  // namespace hotgauge::app
