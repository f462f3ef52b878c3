// core::parallel_for: every index exactly once, the worker ids in range, and an exception from a
// worker thread reaching the caller instead of ending the process.
#include <gtest/gtest.h>

#include <atomic>
#include <stdexcept>
#include <vector>

#include "hotgauge/core/parallel.hpp"

using hotgauge::core::parallel_for;

TEST(ParallelFor, EveryIndexOnce) {
    for (int threads : {0, 1, 3}) {
        std::vector<std::atomic<int>> hits(1000);
        std::atomic<bool> worker_in_range{true};
        const unsigned k = hotgauge::core::worker_count(threads);
        parallel_for(hits.size(), threads, [&](std::size_t i, unsigned worker) {
            ++hits[i];
            if (worker >= k) worker_in_range = false;
        });
        for (std::size_t i = 0; i < hits.size(); ++i) ASSERT_EQ(hits[i], 1) << i;
        EXPECT_TRUE(worker_in_range) << threads;
    }
    parallel_for(0, 2, [](std::size_t, unsigned) { FAIL() << "no work for n = 0"; });
}

TEST(ParallelFor, ExceptionReachesTheCaller) {
    std::atomic<int> done{0};
    EXPECT_THROW(parallel_for(10'000, 2,
                              [&](std::size_t i, unsigned) {
                                  if (i == 100) throw std::runtime_error("piece 100");
                                  ++done;
                              }),
                 std::runtime_error);
    EXPECT_LT(done, 10'000 - 1);  // the handing out stopped early
}
