#pragma once
// Private to the accel module: how a source's reader thread is stopped. The thread polls its
// device fd together with an eventfd; stop sets the flag, wakes the poll, joins, then closes both.
#include <unistd.h>

#include <atomic>
#include <cstdint>
#include <thread>

namespace hotgauge::accel::detail {

inline void stop_worker(std::thread& thread, std::atomic<bool>& stop, int& wake_fd, int& fd) {
    if (thread.joinable()) {
        stop = true;
        const std::uint64_t one = 1;
        (void)!::write(wake_fd, &one, sizeof one);
        thread.join();
    }
    if (fd >= 0) ::close(fd);
    if (wake_fd >= 0) ::close(wake_fd);
    fd = wake_fd = -1;
}

}  // namespace hotgauge::accel::detail
