#pragma once
// Text for the pages the cell serves and the reports it writes (web, report): HTML escaping and
// numbers with a fixed number of decimals. Here, below both, so that the status page needs no
// report (and none of its OpenCV).
#include <string>
#include <string_view>

namespace hotgauge::core {

// `text` with &, <, >, " and ' as entities: safe in element content and quoted attributes.
std::string html_escape(std::string_view text);

// `value` with `decimals` decimals ("62.213"); `sign`: always with its sign ("+0.213").
std::string fixed(double value, int decimals, bool sign = false);

}  // namespace hotgauge::core
