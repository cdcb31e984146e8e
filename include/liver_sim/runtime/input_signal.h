// Wakes the simulation thread when input arrives: any thread calls notify() after handing an
// input over; the simulation thread waits until one came since it last took them, or a
// deadline. ROS-free; what an input is belongs to the caller (tracking_session.h).
#pragma once

#include <chrono>
#include <condition_variable>
#include <mutex>

namespace liver_sim {

class InputSignal {
 public:
  using Clock = std::chrono::steady_clock;
  void notify();
  // True as soon as an input came since the last take() (at once when one had), false at the
  // deadline.
  bool wait_until(Clock::time_point deadline);
  // The inputs so far are being applied: the next wait waits for a newer one.
  void take();

 private:
  std::mutex mutex_;
  std::condition_variable arrived_;
  bool pending_ = false;
};

}  // namespace liver_sim
