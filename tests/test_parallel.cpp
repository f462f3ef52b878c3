// core::parallel_for: every index exactly once, the worker ids in range, and an exception from a
// worker thread reaching the caller instead of ending the process.
#include <gtest/gtest.h>

#include <atomic>
#include <stdexcept>
#include <thread>
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

// On one thread the handing out stops at the piece that threw: nothing after it runs.
TEST(ParallelFor, ExceptionStopsTheHandingOut) {
    int done = 0;
    EXPECT_THROW(parallel_for(10'000, 1,
                              [&](std::size_t i, unsigned) {
                                  if (i == 100) throw std::runtime_error("piece 100");
                                  ++done;
                              }),
                 std::runtime_error);
    EXPECT_EQ(done, 100);
}

// Thrown on a worker thread (not the caller), the exception is rethrown in the caller. The first
// piece of each worker waits (bounded) until both are inside fn, so the spawned worker is sure to
// hold a piece. How many pieces the caller finishes before it sees the stop depends on the
// scheduler (a first throw under ASan is slow), so that count is not asserted here.
TEST(ParallelFor, ExceptionFromAWorkerThreadReachesTheCaller) {
    std::atomic<int> inside{0};
    auto piece = [&](std::size_t i, unsigned worker) {
        if (i < 2) {
            ++inside;
            for (int spin = 0; inside < 2 && spin < 2'000'000; ++spin) std::this_thread::yield();
        }
        if (worker == 1) throw std::runtime_error("worker 1");
    };
    EXPECT_THROW(parallel_for(10'000, 2, piece), std::runtime_error);
    EXPECT_EQ(inside, 2);
}
