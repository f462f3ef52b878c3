#pragma once
// Private to the plant module: its named logger (core/log.hpp).
#include "hotgauge/core/log.hpp"

namespace hotgauge::plant::detail {

inline spdlog::logger& log() {
    static const std::shared_ptr<spdlog::logger> logger = core::module_logger("plant");
    return *logger;
}

}  // namespace hotgauge::plant::detail
