#include "hotgauge/report/html.hpp"

#include <algorithm>
#include <cassert>
#include <cstdio>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

namespace hotgauge::report {
namespace {

// RFC 4648 base64, the encoding of data: URIs (RFC 2397).
std::string base64(const std::vector<std::uint8_t>& bytes) {
    static constexpr char kAlphabet[] =
        "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    std::string out;
    out.reserve((bytes.size() + 2) / 3 * 4);
    for (std::size_t i = 0; i < bytes.size(); i += 3) {
        const std::size_t n = std::min<std::size_t>(3, bytes.size() - i);
        std::uint32_t v = static_cast<std::uint32_t>(bytes[i]) << 16;
        if (n > 1) v |= static_cast<std::uint32_t>(bytes[i + 1]) << 8;
        if (n > 2) v |= bytes[i + 2];
        for (std::size_t k = 0; k < 4; ++k)
            out += k <= n ? kAlphabet[(v >> (18 - 6 * k)) & 63] : '=';
    }
    return out;
}

}  // namespace

std::vector<std::uint8_t> png_bytes(const RgbImage& image) {
    assert(image.width > 0 && image.height > 0);
    // OpenCV wants BGR; the copy is the picture's size, small beside the scan behind it.
    cv::Mat bgr(image.height, image.width, CV_8UC3);
    for (int y = 0; y < image.height; ++y)
        for (int x = 0; x < image.width; ++x) {
            const std::size_t at = (static_cast<std::size_t>(y) * image.width + x) * 3;
            bgr.at<cv::Vec3b>(y, x) = {image.rgb[at + 2], image.rgb[at + 1], image.rgb[at]};
        }
    std::vector<std::uint8_t> png;
    [[maybe_unused]] const bool encoded = cv::imencode(".png", bgr, png);
    assert(encoded);  // an 8-bit 3-channel picture always encodes
    return png;
}

std::string png_data_uri(const RgbImage& image) {
    return "data:image/png;base64," + base64(png_bytes(image));
}

}  // namespace hotgauge::report
