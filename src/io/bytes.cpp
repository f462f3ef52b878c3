#include "hotgauge/io/bytes.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <new>
#include <string>

namespace hotgauge::io {

namespace {

struct Fd {
    int fd = -1;
    explicit Fd(int f) : fd(f) {}
    Fd(const Fd&) = delete;
    Fd& operator=(const Fd&) = delete;
    ~Fd() {
        if (fd >= 0) ::close(fd);
    }
};

// The file open for reading, a regular file only; an Error names it.
core::Result<std::shared_ptr<Fd>> open_regular(const std::filesystem::path& file, struct stat& st) {
    const std::string where = file.string() + ": ";
    // O_NONBLOCK: a FIFO given as a file is refused below instead of waiting for a writer.
    const int fd = ::open(file.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
    if (fd < 0)
        return core::make_error(
            where + (errno == ENOENT ? std::string("missing")
                                     : "cannot open: " + std::string(std::strerror(errno))));
    auto f = std::make_shared<Fd>(fd);
    if (::fstat(f->fd, &st) != 0)
        return core::make_error(where + "cannot stat: " + std::strerror(errno));
    if (!S_ISREG(st.st_mode)) return core::make_error(where + "not a regular file");
    return f;
}

// Up to `n` bytes at `offset` (fewer at the file's end, where a file another process shortens
// while it is read ends: a read, where a mapping would raise SIGBUS); -1 and errno on an error.
ssize_t read_at(int fd, std::uint64_t offset, std::size_t n, unsigned char* out) {
    std::size_t got = 0;
    while (got < n) {
        const ssize_t r = ::pread(fd, out + got, n - got, static_cast<off_t>(offset + got));
        if (r < 0 && errno == EINTR) continue;
        if (r < 0) return -1;
        if (r == 0) break;
        got += static_cast<std::size_t>(r);
    }
    return static_cast<ssize_t>(got);
}

}  // namespace

core::Result<Bytes> read_bytes(const std::filesystem::path& file) {
    const std::string where = file.string() + ": ";
    struct stat st {};
    auto f = open_regular(file, st);
    if (!f) return f.error();
    const auto size = static_cast<std::size_t>(st.st_size);
    std::shared_ptr<unsigned char[]> buffer;
    try {
        buffer.reset(new unsigned char[size ? size : 1]);
    } catch (const std::bad_alloc&) {
        return core::make_error(where + "too large to read (" + std::to_string(size) + " bytes)");
    }
    const ssize_t got = read_at((*f)->fd, 0, size, buffer.get());
    if (got < 0) return core::make_error(where + "read error: " + std::strerror(errno));
    return Bytes{{buffer.get(), static_cast<std::size_t>(got)},
                 std::shared_ptr<const void>(buffer, buffer.get())};
}

core::Result<FileParts> open_parts(const std::filesystem::path& file) {
    struct stat st {};
    auto f = open_regular(file, st);
    if (!f) return f.error();
    FileParts parts;
    parts.size = static_cast<std::uint64_t>(st.st_size);
    parts.read = [fd = std::move(*f), file](std::uint64_t offset, std::size_t n,
                                            void* out) -> core::Result<void> {
        const ssize_t got = read_at(fd->fd, offset, n, static_cast<unsigned char*>(out));
        if (got < 0)
            return core::make_error(file.string() + ": read error: " + std::strerror(errno));
        if (static_cast<std::size_t>(got) < n)
            return core::make_error(file.string() +
                                    ": read error: the file is shorter than it was");
        return {};
    };
    return parts;
}

FileParts FileParts::of(Bytes bytes) {
    FileParts parts;
    parts.size = bytes.data.size();
    parts.read = [bytes = std::move(bytes)](std::uint64_t offset, std::size_t n,
                                            void* out) -> core::Result<void> {
        if (offset > bytes.data.size() || n > bytes.data.size() - offset)
            return core::make_error("read beyond the end of the bytes");
        if (n) std::memcpy(out, bytes.data.data() + offset, n);
        return {};
    };
    return parts;
}

bool exists_on_disk(const std::filesystem::path& path, std::error_code& ec) {
    return std::filesystem::exists(path, ec);
}

}  // namespace hotgauge::io
