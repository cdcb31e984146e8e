#include "liver_sim/runtime/input_signal.h"

namespace liver_sim {

void InputSignal::notify() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    pending_ = true;
  }
  arrived_.notify_one();
}

bool InputSignal::wait_until(Clock::time_point deadline) {
  std::unique_lock<std::mutex> lock(mutex_);
  return arrived_.wait_until(lock, deadline, [this] { return pending_; });
}

void InputSignal::take() {
  std::lock_guard<std::mutex> lock(mutex_);
  pending_ = false;
}

}  // namespace liver_sim
