// Shared by the tests that read the package's own files.
#pragma once

#include <string>

namespace liver_sim {

// A file of the package's sources (LIVER_SIM_SOURCE_DIR), as `path` names it from their top.
inline std::string source(const std::string& path) { return std::string(LIVER_SIM_SOURCE_DIR) + "/" + path; }

}  // namespace liver_sim
