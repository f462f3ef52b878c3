#include "hotgauge/results/sequence.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <charconv>
#include <cstdio>
#include <cstring>
#include <string>

namespace hotgauge::results {
namespace {

constexpr std::size_t kWidth = 20;  // digits of any uint64, then '\n'

}  // namespace

core::Result<SequenceReservation> SequenceReservation::open(const std::filesystem::path& dir) {
    std::error_code ec;  // the results folder, as ResultsLog::open makes it
    std::filesystem::create_directories(dir, ec);
    if (ec)
        return core::make_error(dir.string() +
                                ": cannot create the results folder: " + ec.message());
    const std::filesystem::path path = dir / ".sequence";
    const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (fd < 0) return core::make_error(path.string() + ": " + std::strerror(errno));
    SequenceReservation out(fd, path, 0);
    char buf[kWidth + 2] = {};
    const ssize_t got = ::pread(fd, buf, kWidth + 1, 0);
    if (got < 0) return core::make_error(path.string() + ": " + std::strerror(errno));
    if (got == 0) {
        // New: its line written now (so that later numbers go in place, with no block to
        // allocate on a full disk) and its name synced into the folder.
        if (auto ok = out.reserve(0); !ok) return ok.error();
        const int d = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
        if (d < 0 || ::fsync(d) != 0) {
            const std::string why = std::strerror(errno);
            if (d >= 0) ::close(d);
            return core::make_error(dir.string() + ": " + why);
        }
        ::close(d);
        return out;
    }
    const char* end = buf + got;
    while (end > buf && (end[-1] == '\n' || end[-1] == ' ')) --end;
    const char* first = buf;
    while (first < end && *first == ' ') ++first;
    const auto [ptr, err] = std::from_chars(first, end, out.reserved_);
    if (err != std::errc() || ptr != end || first == end)
        return core::make_error(path.string() +
                                ": not a sequence number (the highest one used): '" +
                                std::string(buf, static_cast<std::size_t>(got)) + "'");
    return out;
}

SequenceReservation::SequenceReservation(SequenceReservation&& o) noexcept
    : fd_(o.fd_), path_(std::move(o.path_)), reserved_(o.reserved_) {
    o.fd_ = -1;
}

SequenceReservation& SequenceReservation::operator=(SequenceReservation&& o) noexcept {
    if (this != &o) {
        if (fd_ >= 0) ::close(fd_);
        fd_ = o.fd_;
        path_ = std::move(o.path_);
        reserved_ = o.reserved_;
        o.fd_ = -1;
    }
    return *this;
}

SequenceReservation::~SequenceReservation() {
    if (fd_ >= 0) ::close(fd_);
}

// Number n's line in place, synced: the bytes written, or -1 (errno says why).
ssize_t SequenceReservation::put(std::uint64_t n) const {
    char line[kWidth + 2];
    std::snprintf(line, sizeof line, "%20llu\n", static_cast<unsigned long long>(n));
    const ssize_t written = ::pwrite(fd_, line, kWidth + 1, 0);
    return written < 0 || ::fdatasync(fd_) != 0 ? -1 : written;
}

core::Result<void> SequenceReservation::reserve(std::uint64_t n) {
    constexpr auto kLine = static_cast<ssize_t>(kWidth + 1);
    const ssize_t written = put(n);
    if (written < 0) return core::make_error(path_.string() + ": " + std::strerror(errno));
    if (written != kLine)  // the old line, partly overwritten: put it back
        return core::make_error(
            path_.string() + ": only " + std::to_string(written) + " of " + std::to_string(kLine) +
            " bytes written" +
            (put(reserved_) == kLine ? "" : ", and the number before could not be put back"));
    reserved_ = n;
    return {};
}

}  // namespace hotgauge::results
