// Paths of the shared real-world test data (../shared/data, see its README).
#pragma once

#include <string>

namespace trailnav::test {

inline std::string shared_data(const std::string& relative) { return "../shared/data/" + relative; }

}  // namespace trailnav::test
