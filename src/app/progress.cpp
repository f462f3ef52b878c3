#include "progress.hpp"

#include <unistd.h>

#include <algorithm>
#include <cmath>

namespace hotgauge::app {
namespace {

std::string minutes_seconds(double s) {
    const auto total = static_cast<long>(std::lround(std::max(0.0, s)));
    char text[32];
    std::snprintf(text, sizeof text, "%ld:%02ld", total / 60, total % 60);
    return text;
}

}  // namespace

Progress::Progress(std::FILE* out, std::size_t total, std::string what)
    : out_(out), tty_(isatty(fileno(out)) != 0), total_(total), what_(std::move(what)) {}

std::string Progress::line(std::size_t done, std::size_t total, const std::string& what,
                           double elapsed_s, int bar_width) {
    const double fraction = total ? static_cast<double>(done) / static_cast<double>(total) : 1.0;
    const auto filled = static_cast<int>(std::floor(fraction * bar_width));
    std::string text = "[" + std::string(static_cast<std::size_t>(filled), '#') +
                       std::string(static_cast<std::size_t>(bar_width - filled), '.') + "] ";
    char counts[160];
    const double rate = elapsed_s > 0 ? static_cast<double>(done) / elapsed_s : 0.0;
    std::snprintf(counts, sizeof counts, "%zu/%zu %s  %.1f %s/s  ", done, total, what.c_str(), rate,
                  what.c_str());
    text += counts;
    if (done >= total)
        text += minutes_seconds(elapsed_s) + " in all";
    else if (rate > 0)
        text += minutes_seconds(static_cast<double>(total - done) / rate) + " left";
    else
        text += "time left not known yet";
    return text;
}

void Progress::draw(std::size_t done, bool last) {
    const double elapsed = std::chrono::duration<double>(Clock::now() - start_).count();
    const std::string text = line(done, total_, what_, elapsed);
    if (tty_)  // redrawn in place; \033[K clears what a longer line left
        std::fprintf(out_, "\r%s\033[K%s", text.c_str(), last ? "\n" : "");
    else
        std::fprintf(out_, "%s\n", text.c_str());
    std::fflush(out_);
    drawn_ = Clock::now();
    plain_done_ = done;
}

void Progress::update(std::size_t done) {
    const auto now = Clock::now();
    if (tty_) {
        if (now - drawn_ >= kRedraw) draw(done, false);
        return;
    }
    const bool step = total_ > 0 && (done - plain_done_) * 100 >= kPlainEvery * total_;
    if (done > plain_done_ && (step || now - drawn_ >= kPlainPeriod)) draw(done, false);
}

void Progress::finish(std::size_t done, const std::string& note) {
    if (tty_ || done != plain_done_ || drawn_ == Clock::time_point{})  // not the last line again
        draw(done, true);
    if (!note.empty()) std::fprintf(out_, "%s\n", note.c_str());
    std::fflush(out_);
}

}  // namespace hotgauge::app
