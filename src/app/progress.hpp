#pragma once
// Progress of a long job on the engineer's terminal: on a terminal one line redrawn in place
// (parts done, parts/s, time left); otherwise (a log, a pipe) a plain line now and then.
#include <chrono>
#include <cstddef>
#include <cstdio>
#include <string>

namespace hotgauge::app {

class Progress {
  public:
    using Clock = std::chrono::steady_clock;
    // `out` is a terminal or not (isatty); `what` names the items ("parts").
    Progress(std::FILE* out, std::size_t total, std::string what);
    // `done` items after `elapsed`; drawn at most every kRedraw on a terminal, every kPlainEvery
    // of the total (or kPlainPeriod) otherwise.
    void update(std::size_t done);
    // The last state, drawn whatever the time, and the line ended.
    void finish(std::size_t done, const std::string& note = "");
    // The text of one state (for tests): "[#####.....]  57/200 parts  10.3 parts/s  0:14 left".
    static std::string line(std::size_t done, std::size_t total, const std::string& what,
                            double elapsed_s, int bar_width = 30);

  private:
    static constexpr auto kRedraw = std::chrono::milliseconds(200);
    static constexpr auto kPlainPeriod = std::chrono::seconds(10);
    static constexpr std::size_t kPlainEvery = 10;  // percent
    void draw(std::size_t done, bool last);
    std::FILE* out_;
    bool tty_;
    std::size_t total_;
    std::string what_;
    Clock::time_point start_ = Clock::now(), drawn_{};
    std::size_t plain_done_ = 0;
};

}  // namespace hotgauge::app
