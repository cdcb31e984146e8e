// The node's frame pacing (frame_pacing.h), without a master: at most ~rate frames a second
// whatever mix of input frames and ticks starts them.
#include <gtest/gtest.h>

#include <algorithm>
#include <thread>
#include <vector>

#include "frame_pacing.h"

namespace liver_sim {
namespace {

using Clock = FramePacing::Clock;

TEST(FramePacing, TicksAndInputFramesTogetherKeepToTheRate) {
  // Every other wait ends at its deadline (a tick), the others find an input at once: the
  // generic cell rate algorithm then allows at most W / T + 1.5 frames in any window W (period
  // T, half a period early allowed). The counts are bounded from above only: a slow machine
  // gives fewer frames. Guards against a tick that does not take its slot, after which an input
  // frame follows at once (a third more frames than the rate; mutation tried: killed).
  const double rate = 50;  // Hz
  const Clock::duration period = std::chrono::milliseconds(20);
  FramePacing pacing(rate, rate);
  std::vector<Clock::time_point> starts;
  bool tick = true;
  const FramePacing::WaitForInput wait = [&](Clock::time_point deadline) {
    tick = !tick;
    if (tick) std::this_thread::sleep_until(deadline);
    return !tick;
  };
  for (int frame = 0; frame < 40; ++frame) {
    pacing.until_next_frame(wait);
    starts.push_back(Clock::now());
  }
  const int window = 10;  // periods
  for (size_t first = 0; first < starts.size(); ++first) {
    const auto end = std::upper_bound(starts.begin(), starts.end(), starts[first] + window * period);
    EXPECT_LE(end - (starts.begin() + first), window + 1) << "frames within " << window << " periods from frame " << first;
  }
}

}  // namespace
}  // namespace liver_sim
