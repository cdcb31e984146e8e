// When the node's frames start and when it publishes, in one place: frames on a fixed grid of
// slots one period of ~rate apart (FrameClock: a late frame's slots are caught up, a held-up
// one's dropped), the mesh and an idle status at most at ~publish_rate, without a burst after
// the loop fell behind.
#pragma once

#include <chrono>

#include "liver_sim/runtime/frame_clock.h"

namespace liver_sim {

class FramePacing {
 public:
  FramePacing(double rate, double publish_rate);
  // From the next frame on (Hz).
  void set_rates(double rate, double publish_rate);
  double rate() const { return rate_; }
  // Whether the mesh (and an idle status) is due now; when it is, the next is a publishing
  // period later.
  bool publish_due();
  // Until the next frame's slot.
  void sleep() { clock_.sleep(); }

 private:
  using Clock = std::chrono::steady_clock;
  FrameClock clock_;
  double rate_, publish_rate_;
  Clock::time_point next_publish_;
};

}  // namespace liver_sim
