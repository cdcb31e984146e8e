#include "liver_sim/runtime/frame_clock.h"

#include <algorithm>
#include <stdexcept>
#include <thread>

namespace liver_sim {

FrameClock::FrameClock(double period, int catch_up, Clock::time_point start) : catch_up_(catch_up), slot_(start) {
  if (catch_up < 0 || catch_up > 1000) throw std::invalid_argument("FrameClock: catch_up must be in [0, 1000] periods");
  set_period(period);
}

void FrameClock::set_period(double period) {
  if (!(period >= 1e-6 && period <= 1e6)) throw std::invalid_argument("FrameClock: period must be in [1e-6, 1e6] s");
  period_ = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(period));
}

FrameClock::Clock::time_point FrameClock::next(Clock::time_point now) {
  slot_ += period_;
  if (now - slot_ > catch_up_ * period_) slot_ = now;
  return std::max(slot_, now);
}

void FrameClock::sleep() { std::this_thread::sleep_until(next(Clock::now())); }

}  // namespace liver_sim
