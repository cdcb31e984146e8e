#include "frame_pacing.h"

#include <algorithm>
#include <utility>

namespace liver_sim {
namespace {

constexpr int kCatchUp = 3;  // periods, as bench's FrameClock (a longer hold-up drops its slots)

}  // namespace

FramePacing::FramePacing(double rate, double publish_rate) : FramePacing(rate, publish_rate, Time()) {}

FramePacing::FramePacing(double rate, double publish_rate, Time time)
    : time_(std::move(time)), rate_(rate), publish_rate_(publish_rate), last_start_(time_.now()),
      last_input_start_(last_start_),
      frame_due_(last_start_), mesh_due_(last_start_),
      next_idle_status_(last_start_) {}

void FramePacing::set_rates(double rate, double publish_rate) {
  rate_ = rate;
  publish_rate_ = publish_rate;
  // What was due at the old rates is due at most a period of the new ones from now.
  const Clock::time_point now = time_.now();
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
  // frame), so that ticks and input frames together keep to the rate. An input frame up to
  // kCatchUp periods late (the thread was busy with a long step, a factorisation) keeps its
  // slot, which the next frames make up: otherwise each long step cost slots for good (the
  // soak's frame rate, doc/robustness.md). A tick's lateness is its design, not made up: a tick
  // then an input frame at once would exceed the rate.
  if (input) time_.sleep_until(frame_due_ - period(rate_) / 2);
  last_start_ = time_.now();
  if (input) last_input_start_ = last_start_;
  const Clock::time_point on_time = input ? last_start_ - kCatchUp * period(rate_) : last_start_;
  frame_due_ = std::max(frame_due_, on_time) + period(rate_);
  return input;
}

bool FramePacing::mesh_due() const { return time_.now() >= mesh_due_ - period(publish_rate_) / 2; }

void FramePacing::mesh_sent() { mesh_due_ = std::max(mesh_due_, time_.now()) + period(publish_rate_); }

bool FramePacing::idle_status_due() {
  const Clock::time_point now = time_.now();
  if (now < next_idle_status_) return false;
  next_idle_status_ = now + period(publish_rate_);
  return true;
}

}  // namespace liver_sim
