#include "frame_pacing.h"

namespace liver_sim {

FramePacing::FramePacing(double rate, double publish_rate)
    : clock_(1.0 / rate, FrameClock::kCatchUp), rate_(rate), publish_rate_(publish_rate), next_publish_(Clock::now()) {}

void FramePacing::set_rates(double rate, double publish_rate) {
  clock_.set_period(1.0 / rate);
  rate_ = rate;
  publish_rate_ = publish_rate;
}

bool FramePacing::publish_due() {
  const Clock::time_point now = Clock::now();
  if (now < next_publish_) return false;
  const auto period = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / publish_rate_));
  next_publish_ += period;
  if (next_publish_ < now) next_publish_ = now + period;  // fell behind: no burst
  return true;
}

}  // namespace liver_sim
