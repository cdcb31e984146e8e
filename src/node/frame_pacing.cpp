#include "frame_pacing.h"

#include <algorithm>
#include <thread>

namespace liver_sim {

FramePacing::FramePacing(double rate, double publish_rate)
    : rate_(rate), publish_rate_(publish_rate), last_start_(Clock::now()), last_input_start_(last_start_),
      frame_due_(last_start_), mesh_due_(last_start_),
      next_idle_status_(last_start_) {}

void FramePacing::set_rates(double rate, double publish_rate) {
  rate_ = rate;
  publish_rate_ = publish_rate;
  // What was due at the old rates is due at most a period of the new ones from now.
  const Clock::time_point now = Clock::now();
  frame_due_ = std::min(frame_due_, now + period(rate_));
  mesh_due_ = std::min(mesh_due_, now + period(publish_rate_));
  next_idle_status_ = std::min(next_idle_status_, now + period(publish_rate_));
}

FramePacing::Clock::duration FramePacing::period(double hz) const {
  return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / hz));
}

bool FramePacing::until_next_frame(const WaitForInput& wait_for_input) {
  // After a frame an input started, the tick waits half a period longer: a stream of inputs at
  // about ~rate then never finds the thread busy with a tick's frame that started just before.
  const Clock::duration tick = last_input_start_ == last_start_ ? period(rate_) * 3 / 2 : period(rate_);
  const bool input = wait_for_input(last_start_ + tick);
  // Frames paced by the generic cell rate algorithm: ~rate a second on average, an input frame up
  // to half a period early (a stream at the rate arrives with jitter and then never waits). A
  // tick takes its slot too (it never waits for it: it comes a period or more after the last
  // frame), so that ticks and input frames together keep to the rate.
  if (input) std::this_thread::sleep_until(frame_due_ - period(rate_) / 2);
  last_start_ = Clock::now();
  if (input) last_input_start_ = last_start_;
  frame_due_ = std::max(frame_due_, last_start_) + period(rate_);
  return input;
}

bool FramePacing::mesh_due() const { return Clock::now() >= mesh_due_ - period(publish_rate_) / 2; }

void FramePacing::mesh_sent() { mesh_due_ = std::max(mesh_due_, Clock::now()) + period(publish_rate_); }

bool FramePacing::idle_status_due() {
  const Clock::time_point now = Clock::now();
  if (now < next_idle_status_) return false;
  next_idle_status_ = now + period(publish_rate_);
  return true;
}

}  // namespace liver_sim
