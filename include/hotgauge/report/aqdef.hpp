#pragma once
// AQDEF export (issue 19, docs/results.md "AQDEF export"): the parts of a results folder as a
// DFQ file in the K-field notation that Q-DAS qs-STAT and other SPC tools read.
#include <string>
#include <vector>

#include "hotgauge/results/read_back.hpp"

namespace hotgauge::report {

// One part type (K1001) per recipe, one characteristic (K2001) per feature; per measured part
// and feature a value block: K0001 value, K0002 attribute, K0004 date/time, K0006 part id,
// K0014 the part id (batch/ident and part ident), K0009 "seq N" (the results files' sequence
// number) and the reason when there is one. A value not measured has
// an empty K0001 and attribute 255, never a number; a degraded value keeps its number with
// attribute 255 (left out of the evaluation, as in the lot report). Master checks are left out.
// Lines end in CR LF; the text is ASCII (other characters become '?').
std::string aqdef_dfq(const std::vector<results::PartRecord>& parts);

// "2026-12-04T17:50:01.426+01:00" → "04.12.2026/17:50:01" (AQDEF K0004: local time).
std::string aqdef_time(const std::string& iso_local);

}  // namespace hotgauge::report
