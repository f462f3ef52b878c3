#include "hotgauge/results/sequence.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <charconv>
#include <cstdio>
#include <cstring>
#include <optional>
#include <sstream>
#include <string>
#include <string_view>

namespace hotgauge::results {
namespace {

constexpr std::size_t kLine = 40;  // "%20llu %10u %5u %c\n"
constexpr std::string_view kStates = "RDS";

// The line as written, or the old one (a number alone).
std::optional<SequenceReservation::Use> parse(const std::string& text) {
    std::istringstream in(text);
    SequenceReservation::Use use;
    std::string part, slot, state, extra;
    if (!(in >> use.sequence)) return std::nullopt;
    if (!(in >> part)) return in.eof() ? std::optional(use) : std::nullopt;
    unsigned long long p = 0, s = 0;
    if (!(in >> slot >> state) || (in >> extra) || state.size() != 1 ||
        kStates.find(state[0]) == std::string_view::npos ||
        std::from_chars(part.data(), part.data() + part.size(), p).ec != std::errc() ||
        std::from_chars(slot.data(), slot.data() + slot.size(), s).ec != std::errc() ||
        p > UINT32_MAX || s > UINT16_MAX)
        return std::nullopt;
    use.part_id = static_cast<std::uint32_t>(p);
    use.slot = static_cast<std::uint16_t>(s);
    use.state = state[0];
    return use;
}

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
    SequenceReservation out(fd, path);
    char buf[kLine + 2] = {};
    const ssize_t got = ::pread(fd, buf, kLine + 1, 0);
    if (got < 0) return core::make_error(path.string() + ": " + std::strerror(errno));
    if (got == 0) {
        // New: its line written now (so that later numbers go in place, with no block to
        // allocate on a full disk) and its name synced into the folder.
        if (auto ok = out.keep({}); !ok) return ok.error();
        const int d = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
        if (d < 0 || ::fsync(d) != 0) {
            const std::string why = std::strerror(errno);
            if (d >= 0) ::close(d);
            return core::make_error(dir.string() + ": " + why);
        }
        ::close(d);
        return out;
    }
    const std::string text(buf, static_cast<std::size_t>(got));
    const auto use = parse(text);
    if (!use)
        return core::make_error(path.string() +
                                ": not a sequence number (the highest one used): '" + text + "'");
    out.last_ = *use;
    return out;
}

SequenceReservation::SequenceReservation(SequenceReservation&& o) noexcept
    : fd_(o.fd_), path_(std::move(o.path_)), last_(o.last_) {
    o.fd_ = -1;
}

SequenceReservation& SequenceReservation::operator=(SequenceReservation&& o) noexcept {
    if (this != &o) {
        if (fd_ >= 0) ::close(fd_);
        fd_ = o.fd_;
        path_ = std::move(o.path_);
        last_ = o.last_;
        o.fd_ = -1;
    }
    return *this;
}

SequenceReservation::~SequenceReservation() {
    if (fd_ >= 0) ::close(fd_);
}

// The line in place, synced: the bytes written, or -1 (errno says why).
ssize_t SequenceReservation::put(const Use& use) const {
    char line[kLine + 1];
    std::snprintf(line, sizeof line, "%20llu %10u %5u %c\n",
                  static_cast<unsigned long long>(use.sequence), use.part_id,
                  static_cast<unsigned>(use.slot), use.state);
    const ssize_t written = ::pwrite(fd_, line, kLine, 0);
    return written < 0 || ::fdatasync(fd_) != 0 ? -1 : written;
}

core::Result<void> SequenceReservation::keep(const Use& use) {
    const ssize_t written = put(use);
    if (written < 0) return core::make_error(path_.string() + ": " + std::strerror(errno));
    if (written != static_cast<ssize_t>(kLine))  // the old line, partly overwritten: put it back
        return core::make_error(path_.string() + ": only " + std::to_string(written) + " of " +
                                std::to_string(kLine) + " bytes written" +
                                (put(last_) == static_cast<ssize_t>(kLine)
                                     ? ""
                                     : ", and the line before could not be put back"));
    last_ = use;
    return {};
}

core::Result<void> SequenceReservation::reserve(std::uint64_t n, std::uint32_t part_id,
                                                std::uint16_t slot) {
    return keep({n, part_id, slot, 'R'});
}

core::Result<void> SequenceReservation::taken() {
    Use use = last_;
    use.state = 'D';
    return keep(use);
}

core::Result<void> SequenceReservation::stopped() {
    Use use = last_;
    use.state = 'S';
    return keep(use);
}

}  // namespace hotgauge::results
