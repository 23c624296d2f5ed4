// Rows of numbers from a small text file (ground truth, a drive's poses): the
// fields separated by commas or spaces, empty lines and lines beginning with
// '#' skipped, a first line that is not numbers taken for a header. Offline
// tools only.
#pragma once

#include <cstddef>
#include <functional>
#include <span>
#include <string>
#include <string_view>

namespace trailnav::eval {

// Each row's numbers go to `row` with its 1-based line number; `row` returns
// "" or what is wrong with them. A row of fewer than `min_fields` or more
// than `max_fields` fields, or a field that is not a number, is refused with
// `expected` (the format, e.g. "`time,x,y,yaw[,lat,lon]`"). Returns "" or
// "path:line: what" ("path: cannot read" when it cannot be opened).
std::string read_number_rows(const std::string& path, std::size_t min_fields, std::size_t max_fields,
                             std::string_view expected,
                             const std::function<std::string(int line, std::span<const double> fields)>& row);

}  // namespace trailnav::eval
