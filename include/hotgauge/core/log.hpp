#pragma once
// A module's named spdlog logger ("accel", "vcell", ...), sharing the default logger's sinks and
// taking its level from SPDLOG_LEVEL like every registered logger (style.md §8). Header-only so
// that core stays free of spdlog at link time.
#include <spdlog/spdlog.h>

#include <memory>
#include <string>

namespace hotgauge::core {

inline std::shared_ptr<spdlog::logger> module_logger(const std::string& name) {
    if (auto existing = spdlog::get(name)) return existing;
    const auto& sinks = spdlog::default_logger()->sinks();
    auto made = std::make_shared<spdlog::logger>(name, sinks.begin(), sinks.end());
    try {
        spdlog::initialize_logger(made);
    } catch (const spdlog::spdlog_ex&) {  // registered meanwhile by another thread
        if (auto existing = spdlog::get(name)) return existing;
    }
    return made;
}

}  // namespace hotgauge::core
