// The stepper's phase times (StepTiming): wall time since t0 in milliseconds.
#pragma once

#include <chrono>

namespace liver_sim {

inline double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace liver_sim
