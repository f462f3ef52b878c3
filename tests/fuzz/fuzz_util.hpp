#pragma once
// Shared by the libFuzzer harnesses (tests/fuzz/README.md): a scratch folder per process for the
// file-based readers, and the checks every harness makes. A failed check prints what was wrong and
// aborts, which libFuzzer reports as a crash and saves as crash-<sha1>.
#include <cxxabi.h>
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <string>
#include <string_view>
#include <typeinfo>

#include "hotgauge/core/result.hpp"

namespace hotgauge::fuzz {

// A fresh folder for this process under $FUZZ_SCRATCH (run.sh sets it and removes it after the
// run: libFuzzer ends with _Exit, so atexit cleanup would not run), else under /dev/shm when
// there is one (no disk I/O), else the temporary folder. Parallel runs (-jobs, -fork) get one each.
inline const std::filesystem::path& scratch_dir(const char* harness) {
    static const std::filesystem::path dir = [harness] {
        namespace fs = std::filesystem;
        std::error_code ec;
        const char* env = std::getenv("FUZZ_SCRATCH");
        const fs::path base = env && *env                        ? fs::path(env)
                              : fs::is_directory("/dev/shm", ec) ? fs::path("/dev/shm")
                                                                 : fs::temp_directory_path();
        fs::path d = base / ("hotgauge-" + std::string(harness) + "-" + std::to_string(::getpid()));
        fs::remove_all(d, ec);
        fs::create_directories(d);
        return d;
    }();
    return dir;
}

// Writes `size` bytes to `path` (replacing it); aborts when it cannot, since that is the
// harness's environment failing, not the reader.
inline void write_file(const std::filesystem::path& path, const std::uint8_t* data,
                       std::size_t size) {
    std::FILE* f = std::fopen(path.c_str(), "wb");
    if (!f || (size && std::fwrite(data, 1, size, f) != size) || std::fclose(f) != 0) {
        std::fprintf(stderr, "harness: cannot write %s\n", path.c_str());
        std::abort();
    }
}

// The whole input as the file `name` in this process's scratch folder.
inline std::filesystem::path input_file(const char* harness, const char* name,
                                        const std::uint8_t* data, std::size_t size) {
    std::filesystem::path path = scratch_dir(harness) / name;
    write_file(path, data, size);
    return path;
}

[[noreturn]] inline void fail(const std::string& what) {
    std::fprintf(stderr, "FUZZ CHECK FAILED: %s\n", what.c_str());
    std::abort();
}

inline void check(bool ok, const std::string& what) {
    if (!ok) fail(what);
}

// Calls a reader that promises a core::Result: an exception escaping it is a finding, reported
// with its message (an uncaught one would only say "terminate called").
template <class Reader>
auto no_throw(const char* name, Reader&& reader) -> decltype(reader()) {
    try {
        return reader();
    } catch (const std::exception& e) {
        int status = 0;
        char* type = abi::__cxa_demangle(typeid(e).name(), nullptr, nullptr, &status);
        fail(std::string(name) + " threw " + (type ? type : typeid(e).name()) + ": " + e.what());
    } catch (...) {
        fail(std::string(name) + " threw a non-std exception");
    }
}

// Every reader's errors start with the file (or folder) they concern.
inline void check_error_names(const core::Error& e, const std::filesystem::path& path) {
    check(std::string_view(e.message).starts_with(path.string()),
          "error does not name " + path.string() + ": " + e.message);
}

}  // namespace hotgauge::fuzz
