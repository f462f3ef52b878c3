// hotgauged: the inspection cell's daemon (docs/operations.md). Exit codes: 0 stopped by
// SIGTERM/SIGINT, 1 could not start (config, PLC port, devices), 2 bad command line.
//   hotgauged --config FILE                 run (under systemd: Type=notify, watchdog, journald)
//   hotgauged --config FILE --check-config  validate the config and everything it names, then exit
#include <pthread.h>
#include <signal.h>
#include <spdlog/cfg/env.h>
#include <spdlog/spdlog.h>
#include <systemd/sd-daemon.h>

#include <CLI/CLI.hpp>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <thread>

#include "hotgauge/cell/daemon.hpp"
#include "hotgauge/cell/journal.hpp"

namespace {

using namespace hotgauge;

// sd_notify, with WATCHDOG=1 sent at most every half of WatchdogSec (nothing outside systemd).
cell::Supervisor systemd_supervisor() {
    std::uint64_t usec = 0;
    const bool watchdog = sd_watchdog_enabled(0, &usec) > 0;
    const auto period = std::chrono::microseconds(usec / 2);
    auto last = std::make_shared<std::chrono::steady_clock::time_point>();
    cell::Supervisor s;
    s.ready = [] { sd_notify(0, "READY=1\nSTATUS=idle: waiting for a trigger"); };
    s.status = [](const std::string& text) { sd_notify(0, ("STATUS=" + text).c_str()); };
    s.stopping = [](const std::string& text) {
        sd_notify(0, ("STOPPING=1\nSTATUS=" + text).c_str());
    };
    if (watchdog)
        s.watchdog = [last, period] {
            const auto now = std::chrono::steady_clock::now();
            if (now - *last < period) return;
            *last = now;
            sd_notify(0, "WATCHDOG=1");
        };
    return s;
}

}  // namespace

int main(int argc, char** argv) {
    cell::init_logging("hotgauged");
    spdlog::cfg::load_env_levels();
    CLI::App app{"hotgauged: the inspection cell's daemon (docs/operations.md)"};
    std::string config = "/etc/hotgauge/hotgauged.yaml";
    bool check = false;
    app.add_option("--config", config, "the daemon's YAML config")->capture_default_str();
    app.add_flag("--check-config", check,
                 "validate the config, the recipes, models and calibration it names, then exit");
    app.set_version_flag("--version", std::string(HOTGAUGE_VERSION));
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        return app.exit(e) == 0 ? 0 : 2;
    }

    // A results file over the size limit (RLIMIT_FSIZE) is a write error to report, not a kill.
    signal(SIGXFSZ, SIG_IGN);
    // Signals go to one thread (sigwait), never into the workers.
    sigset_t signals;
    sigemptyset(&signals);
    sigaddset(&signals, SIGTERM);
    sigaddset(&signals, SIGINT);
    sigaddset(&signals, SIGHUP);
    pthread_sigmask(SIG_BLOCK, &signals, nullptr);

    auto setup = cell::load_setup(config);
    if (!setup) {
        spdlog::error("{}", setup.error().message);
        return 1;
    }
    if (check) {
        std::printf("%s: OK\n%s", config.c_str(), cell::describe(**setup).c_str());
        return 0;
    }
    auto daemon = cell::Daemon::start(*setup, systemd_supervisor());
    if (!daemon) {
        spdlog::error("{}", daemon.error().message);
        return 1;
    }
    std::atomic<bool> done{false};
    std::thread signal_thread([&] {
        while (!done) {
            int sig = 0;
            if (sigwait(&signals, &sig) != 0) continue;
            if (sig == SIGHUP) {
                spdlog::info("SIGHUP: reload between parts");
                (*daemon)->request_reload();
            } else {
                spdlog::info("{}: stopping", sig == SIGTERM ? "SIGTERM" : "SIGINT");
                (*daemon)->request_stop();
                return;
            }
        }
    });
    (*daemon)->run();
    done = true;
    pthread_kill(signal_thread.native_handle(), SIGTERM);  // if run() ended on its own
    signal_thread.join();
    spdlog::info("hotgauged stopped");
    return 0;
}
