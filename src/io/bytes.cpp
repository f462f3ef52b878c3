#include "hotgauge/io/bytes.hpp"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <string>

namespace hotgauge::io {

namespace {

// Below this a read costs less than setting up and tearing down a mapping.
constexpr off_t kMapFrom = 256 * 1024;

struct Fd {
    int fd = -1;
    ~Fd() {
        if (fd >= 0) ::close(fd);
    }
};

}  // namespace

core::Result<Bytes> read_bytes(const std::filesystem::path& file) {
    const std::string where = file.string() + ": ";
    // O_NONBLOCK: a FIFO given as a file is refused below instead of waiting for a writer.
    Fd f{::open(file.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK)};
    if (f.fd < 0)
        return core::make_error(
            where + (errno == ENOENT ? std::string("missing")
                                     : "cannot open: " + std::string(std::strerror(errno))));
    struct stat st {};
    if (::fstat(f.fd, &st) != 0)
        return core::make_error(where + "cannot stat: " + std::strerror(errno));
    if (!S_ISREG(st.st_mode)) return core::make_error(where + "not a regular file");
    const auto size = static_cast<std::size_t>(st.st_size);
    if (st.st_size >= kMapFrom) {
        void* p = ::mmap(nullptr, size, PROT_READ, MAP_PRIVATE, f.fd, 0);
        if (p != MAP_FAILED) {
            std::shared_ptr<const void> owner(
                p, [size](const void* q) { ::munmap(const_cast<void*>(q), size); });
            return Bytes{{static_cast<const unsigned char*>(p), size}, std::move(owner)};
        }
    }
    auto buffer = std::shared_ptr<unsigned char[]>(new unsigned char[size ? size : 1]);
    std::size_t got = 0;
    while (got < size) {
        const ssize_t n = ::read(f.fd, buffer.get() + got, size - got);
        if (n < 0 && errno == EINTR) continue;
        if (n < 0) return core::make_error(where + "read error: " + std::strerror(errno));
        if (n == 0) return core::make_error(where + "read error: the file shrank while read");
        got += static_cast<std::size_t>(n);
    }
    return Bytes{{buffer.get(), size}, std::shared_ptr<const void>(buffer, buffer.get())};
}

bool exists_on_disk(const std::filesystem::path& path, std::error_code& ec) {
    return std::filesystem::exists(path, ec);
}

}  // namespace hotgauge::io
