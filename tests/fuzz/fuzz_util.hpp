#pragma once
// Shared by the libFuzzer harnesses (tests/fuzz/README.md): the names and the file system the
// in-memory readers are given, and the checks every harness makes. A failed check prints what was
// wrong and aborts, which libFuzzer reports as a crash and saves as crash-<sha1>.
#include <cxxabi.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <string>
#include <string_view>
#include <system_error>
#include <typeinfo>
#include <vector>

#include "hotgauge/core/result.hpp"
#include "hotgauge/io/bytes.hpp"

namespace hotgauge::fuzz {

// The folder the harnesses' inputs are named in: no file is written or read, the readers take
// the input's bytes and these names for their messages.
inline const std::filesystem::path kDir = "fuzz";

// A file system that has exactly `files` under kDir; a name longer than a file system's 255
// bytes cannot be looked at (the error a real one gives), everything else does not exist.
inline io::PathExists files_exist(std::vector<std::string> files) {
    return [files = std::move(files)](const std::filesystem::path& p, std::error_code& ec) {
        if (p.filename().string().size() > 255) {
            ec = std::make_error_code(std::errc::filename_too_long);
            return false;
        }
        ec.clear();
        for (const auto& f : files)
            if (p == kDir / f) return true;
        return false;
    };
}

// The input as text.
inline std::string_view text_of(const std::uint8_t* data, std::size_t size) {
    return {reinterpret_cast<const char*>(data), size};
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
