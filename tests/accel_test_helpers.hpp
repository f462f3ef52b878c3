#pragma once
// Test helpers for the accelerometer sources' tests (test_accel, test_accel_contract): samples
// compared bit for bit (NaNs too), a bounded wait, and a fake sysfs tree's one-line files.
#include <gtest/gtest.h>

#include <bit>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <thread>
#include <vector>

#include "hotgauge/accel/ring.hpp"

namespace hotgauge::test {

inline bool same_bits(float a, float b) {
    return std::bit_cast<std::uint32_t>(a) == std::bit_cast<std::uint32_t>(b);
}

inline void expect_samples_eq(const std::vector<accel::AccelSample>& got,
                              const std::vector<accel::AccelSample>& want) {
    ASSERT_EQ(got.size(), want.size());
    for (std::size_t i = 0; i < got.size(); ++i) {
        EXPECT_EQ(got[i].t_ns, want[i].t_ns) << "sample " << i;
        EXPECT_TRUE(same_bits(got[i].x_mps2, want[i].x_mps2)) << "sample " << i;
        EXPECT_TRUE(same_bits(got[i].y_mps2, want[i].y_mps2)) << "sample " << i;
        EXPECT_TRUE(same_bits(got[i].z_mps2, want[i].z_mps2)) << "sample " << i;
    }
}

// A bounded wait on a condition nobody notifies (a thread's state, a counter it updates after
// the ring push the test waited for).
inline bool eventually(const std::function<bool()>& done,
                       std::chrono::milliseconds timeout = std::chrono::seconds(5)) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (!done()) {
        if (std::chrono::steady_clock::now() > deadline) return false;
        std::this_thread::yield();
    }
    return true;
}

// A sysfs attribute: one line written, one line read back.
inline void write_text(const std::filesystem::path& p, const std::string& text) {
    std::filesystem::create_directories(p.parent_path());
    std::ofstream(p, std::ios::trunc) << text << "\n";
}
inline std::string read_line(const std::filesystem::path& p) {
    std::ifstream in(p);
    std::string s;
    std::getline(in, s);
    return s;
}

}  // namespace hotgauge::test
