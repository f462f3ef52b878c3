#include "hotgauge/cell/status_board.hpp"

#include <chrono>
#include <exception>

#include "hotgauge/core/clock.hpp"
#include "hotgauge/report/part_report.hpp"
#include "hotgauge/results/read_back.hpp"
#include "hotgauge/results/results_log.hpp"

namespace hotgauge::cell {
namespace {

namespace fs = std::filesystem;

constexpr std::size_t kKeepArchived = 5;
constexpr int kPictureSidePx = 400;

// The range image of every scanned face (report::range_png), timed.
std::vector<web::PictureView> draw_pictures(const core::Recording& rec, double& ms) {
    const auto t0 = std::chrono::steady_clock::now();
    std::vector<web::PictureView> out;
    for (const auto& face : rec.faces) {
        auto p = report::range_png(face, kPictureSidePx);
        if (p.png.empty()) continue;
        out.push_back({p.face, p.width, p.height,
                       std::make_shared<const std::vector<std::uint8_t>>(std::move(p.png))});
    }
    ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    return out;
}

web::ResultView result_view(const results::PartRecord& p, const std::string& outcome) {
    web::ResultView r{p.sequence, p.time, p.part_id, p.recipe, p.verdict, outcome, {}};
    for (const auto& f : p.features) r.features.push_back({f.name, f.cold_mm, f.verdict, f.reason});
    return r;
}

template <typename T>
void push_front_bounded(std::vector<T>& list, T item, std::size_t keep) {
    list.insert(list.begin(), std::move(item));
    if (list.size() > keep) list.resize(keep);
}

}  // namespace

StatusBoard::StatusBoard(const fs::path& results_dir, const fs::path& archive_dir,
                         std::size_t keep_results, std::size_t keep_events)
    : results_dir_(results_dir.lexically_normal()),
      archive_dir_(archive_dir.lexically_normal()),
      keep_results_(keep_results),
      keep_events_(keep_events) {}

std::vector<web::FileRoot> StatusBoard::roots() const {
    return {{"results", results_dir_}, {"archive", archive_dir_}};
}

std::string StatusBoard::href(const fs::path& file) const {
    for (const auto& root : roots()) {
        const fs::path rel = file.lexically_normal().lexically_relative(root.dir);
        if (rel.empty() || *rel.begin() == "..") continue;
        return "/" + root.name + "/" + rel.generic_string();
    }
    return "";
}

void StatusBoard::set_state(const std::string& state) {
    std::lock_guard lock(mutex_);
    view_.state = state;
}

void StatusBoard::set_health(const DeviceHealth& health) {
    std::lock_guard lock(mutex_);
    health_ = health;
}

void StatusBoard::event(const std::string& text, bool fault) {
    std::lock_guard lock(mutex_);
    push_front_bounded(view_.events, {results::local_iso8601(core::realtime_ns()), text, fault},
                       keep_events_);
}

void StatusBoard::part(const PartNews& news) {
    double ms = 0;
    std::vector<web::PictureView> pictures;
    if (news.recording && !news.recording->faces.empty())
        pictures = draw_pictures(*news.recording, ms);
    results::PartRecord record;
    try {
        record = results::parse_result_line(news.jsonl_line);
    } catch (const std::exception& e) {  // a bug: the daemon's own line; shown, not thrown
        event(std::string("status page: cannot read the part's results line: ") + e.what(), true);
        return;
    }
    std::lock_guard lock(mutex_);
    push_front_bounded(view_.results, result_view(record, news.outcome), keep_results_);
    if (news.problem)
        push_front_bounded(view_.events, {record.time, news.message, true}, keep_events_);
    if (!pictures.empty()) {
        view_.pictures = std::move(pictures);
        view_.pictures_sequence = record.sequence;
        view_.pictures_part_id = record.part_id;
        view_.pictures_ms = ms;
    }
    day_ = record.time.substr(0, 10);
    day_files_ = news.files;
    if (news.archived) archived_.push_front(*news.archived);
    while (archived_.size() > kKeepArchived) archived_.pop_back();
}

web::CellView StatusBoard::view() const {
    std::lock_guard lock(mutex_);
    web::CellView v = view_;
    if (health_.updated_ns != 0) {
        v.health_updated = results::local_iso8601(health_.updated_ns);
        for (int d = 0; d < kDeviceCount; ++d) {
            const auto& s = health_.devices[static_cast<std::size_t>(d)];
            v.devices.push_back({to_string(static_cast<Device>(d)), s.configured, s.ok, s.detail});
        }
    }
    std::vector<fs::path> files = day_files_;
    if (!day_.empty()) files.push_back(results_dir_ / (day_ + ".report.html"));
    for (const auto& f : files)
        if (auto h = href(f); !h.empty() && fs::exists(f))
            v.files.push_back({f.filename().string(), h});
    for (const auto& f : archived_)
        if (auto h = href(f); !h.empty() && fs::exists(f))
            v.files.push_back({"recording " + f.filename().string(), h + "/"});
    v.files.push_back({"every results file", "/results/"});
    v.files.push_back({"the raw archive", "/archive/"});
    return v;
}

}  // namespace hotgauge::cell
