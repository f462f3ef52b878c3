#pragma once
// What the readers read. Every reader has an entry point on bytes, named for its messages (tests
// and the fuzz harnesses call it, with no file system: tests/fuzz/README.md), and a file entry
// point that reads the bytes with read_bytes and passes the file's name. What a reader asks the
// file system besides (does a file the recipe names exist? the files of a recording's folder) is
// passed in as a function, which a harness answers from memory.
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <system_error>

#include "hotgauge/core/result.hpp"

namespace hotgauge::io {

// A file's bytes. `owner` keeps them alive (the buffer they were read into); null when the
// caller keeps them (view()).
struct Bytes {
    std::span<const unsigned char> data;
    std::shared_ptr<const void> owner;

    std::string_view text() const {
        return {reinterpret_cast<const char*>(data.data()), data.size()};
    }
    // Bytes the caller keeps alive while they are read.
    static Bytes view(std::string_view s) {
        return {{reinterpret_cast<const unsigned char*>(s.data()), s.size()}, nullptr};
    }
    static Bytes view(std::string&&) = delete;  // a temporary would be gone before the read
};

// The whole file (a regular file only: a folder, a FIFO or a device is refused). An Error names
// the file: "FILE: missing", "not a regular file", "cannot open: <why>", "read error: <why>",
// "too large to read".
core::Result<Bytes> read_bytes(const std::filesystem::path& file);

// A file read in parts: its size, then the bytes a reader needs, where it needs them. A large
// file's header is checked before its data is read (a header that announces 4 GiB costs nothing),
// and the data lands straight in the reader's own buffer: one copy.
struct FileParts {
    std::uint64_t size = 0;
    // `n` bytes at `offset` into `out`; an Error names the file (one that shrank included).
    std::function<core::Result<void>(std::uint64_t offset, std::size_t n, void* out)> read;

    // Bytes in memory (alive while `bytes.owner` or the caller keeps them).
    static FileParts of(Bytes bytes);
};
// A file on disk, opened (a regular file only); read() reads it with pread.
core::Result<FileParts> open_parts(const std::filesystem::path& file);

// Files by path, as a reader of several files asks for them (a recording's part.yaml, its faces'
// arrays): open_parts on disk, a table in memory. A file it does not have is an Error naming it.
using FileSource = std::function<core::Result<FileParts>(const std::filesystem::path& file)>;

// Does `path` exist? Sets `ec` when it cannot be told (a name too long, a symlink loop, no
// permission).
using PathExists = std::function<bool(const std::filesystem::path& path, std::error_code& ec)>;
bool exists_on_disk(const std::filesystem::path& path, std::error_code& ec);

// A reader's file entry point: `parse(text, file)` on the file's bytes.
template <class Parse>
auto parse_file(const std::filesystem::path& file, Parse&& parse)
    -> decltype(parse(std::string_view{}, file)) {
    auto bytes = read_bytes(file);
    if (!bytes) return bytes.error();
    return parse(bytes->text(), file);
}

}  // namespace hotgauge::io
