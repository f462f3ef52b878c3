#pragma once
// Test helper: two linked pseudo-terminals from socat, standing in for a serial cable (the
// pyrometer's RS-485 link): what is written to a() is read from b() and back.
#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <string>
#include <thread>

#include "temp_dir.hpp"

extern char** environ;

namespace hotgauge::test {

class SerialPair {
  public:
    SerialPair() : a_((dir_.path / "a").string()), b_((dir_.path / "b").string()) {
        const std::string l1 = "pty,raw,echo=0,link=" + a_, l2 = "pty,raw,echo=0,link=" + b_;
        const char* argv[] = {"socat", "-d", "-d", l1.c_str(), l2.c_str(), nullptr};
        posix_spawn_file_actions_t fa;
        posix_spawn_file_actions_init(&fa);
        posix_spawn_file_actions_addopen(&fa, 2, "/dev/null", O_WRONLY, 0);
        ok_ = posix_spawnp(&pid_, "socat", &fa, nullptr, const_cast<char**>(argv), environ) == 0;
        posix_spawn_file_actions_destroy(&fa);
        const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
        while (ok_ && !(std::filesystem::exists(a_) && std::filesystem::exists(b_))) {
            if (std::chrono::steady_clock::now() > deadline) ok_ = false;
            std::this_thread::sleep_for(std::chrono::milliseconds(10));
        }
    }
    ~SerialPair() {
        if (pid_ <= 0) return;
        ::kill(pid_, SIGTERM);
        int status = 0;
        ::waitpid(pid_, &status, 0);
    }
    SerialPair(const SerialPair&) = delete;
    SerialPair& operator=(const SerialPair&) = delete;
    bool ok() const { return ok_; }  // socat runs and both ends exist
    const std::string& a() const { return a_; }
    const std::string& b() const { return b_; }

  private:
    TempDir dir_;
    std::string a_, b_;
    pid_t pid_ = -1;
    bool ok_ = false;
};

}  // namespace hotgauge::test
