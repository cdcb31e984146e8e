// Shared by the tests of threads: the threads of this process.
#pragma once

#include <filesystem>

namespace liver_sim {

// Threads of this process, as the kernel lists them.
inline int process_threads() {
  int n = 0;
  for ([[maybe_unused]] const auto& entry : std::filesystem::directory_iterator("/proc/self/task")) ++n;
  return n;
}

}  // namespace liver_sim
