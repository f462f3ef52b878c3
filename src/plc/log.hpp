#pragma once
// Private to the plc module: its named spdlog logger ("plc"), sharing the default logger's
// sinks and taking its level from SPDLOG_LEVEL like every registered logger (style.md §8).
#include <spdlog/spdlog.h>

#include <memory>

namespace hotgauge::plc::detail {

inline spdlog::logger& log() {
    static const std::shared_ptr<spdlog::logger> logger = [] {
        if (auto existing = spdlog::get("plc")) return existing;
        const auto& sinks = spdlog::default_logger()->sinks();
        auto made = std::make_shared<spdlog::logger>("plc", sinks.begin(), sinks.end());
        try {
            spdlog::initialize_logger(made);
        } catch (const spdlog::spdlog_ex&) {  // registered meanwhile by someone else: use ours
        }
        return made;
    }();
    return *logger;
}

}  // namespace hotgauge::plc::detail
