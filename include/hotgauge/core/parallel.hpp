#pragma once
// Independent pieces of one part's processing spread over the cores (the cell PC has two).
#include <algorithm>
#include <atomic>
#include <cstddef>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace hotgauge::core {

// How many threads `parallel_for` uses for `threads` (0: one per core).
inline unsigned worker_count(int threads = 0) {
    if (threads > 0) return static_cast<unsigned>(threads);
    return std::clamp(std::thread::hardware_concurrency(), 1u, 16u);
}

// fn(i, worker) for every i in [0, n) on up to worker_count(threads) threads, the caller being
// worker 0. Indices are handed out one at a time, in order, so uneven pieces balance out. The
// worker id lets each thread own scratch space; results must be written per index (never
// appended), so that they do not depend on the interleaving. An exception thrown by fn (say
// std::bad_alloc) stops the handing out and is rethrown here once every thread has stopped,
// as from a plain loop, instead of ending the process from a worker thread.
template <class Fn>
void parallel_for(std::size_t n, int threads, const Fn& fn) {
    const auto k = std::min<std::size_t>(n, worker_count(threads));
    std::atomic<std::size_t> next{0};
    std::exception_ptr failed;
    std::mutex failed_mutex;
    auto work = [&](unsigned worker) {
        try {
            for (std::size_t i = next++; i < n; i = next++) fn(i, worker);
        } catch (...) {
            next = n;
            const std::lock_guard lock(failed_mutex);
            if (!failed) failed = std::current_exception();
        }
    };
    std::vector<std::thread> pool;
    for (unsigned t = 1; t < k; ++t) pool.emplace_back(work, t);
    work(0);
    for (auto& t : pool) t.join();
    if (failed) std::rethrow_exception(failed);
}

}  // namespace hotgauge::core
