#include "frame_pacing.h"

#include <algorithm>
#include <thread>

namespace liver_sim {

FramePacing::FramePacing(double rate, double publish_rate)
    : rate_(rate), publish_rate_(publish_rate), last_start_(Clock::now()), last_input_start_(last_start_),
      input_due_(last_start_), next_publish_(last_start_) {}

void FramePacing::set_rates(double rate, double publish_rate) {
  rate_ = rate;
  publish_rate_ = publish_rate;
}

FramePacing::Clock::duration FramePacing::period(double hz) const {
  return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / hz));
}

bool FramePacing::until_next_frame(const WaitForInput& wait_for_input) {
  // After a frame an input started, the tick waits half a period longer: a stream of inputs at
  // about ~rate then never finds the thread busy with a tick's frame that started just before.
  const Clock::duration tick = last_input_start_ == last_start_ ? period(rate_) * 3 / 2 : period(rate_);
  const bool input = wait_for_input(last_start_ + tick);
  // Input frames paced by the generic cell rate algorithm: ~rate a second on average, one up to
  // half a period early (a stream at the rate arrives with jitter and then never waits).
  if (input) std::this_thread::sleep_until(input_due_ - period(rate_) / 2);
  last_start_ = Clock::now();
  if (input) {
    last_input_start_ = last_start_;
    input_due_ = std::max(input_due_, last_start_) + period(rate_);
  }
  return input;
}

bool FramePacing::publish_due() {
  const Clock::time_point now = Clock::now();
  if (now < next_publish_) return false;
  next_publish_ += period(publish_rate_);
  if (next_publish_ < now) next_publish_ = now + period(publish_rate_);  // fell behind: no burst
  return true;
}

}  // namespace liver_sim
