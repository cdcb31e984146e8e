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

// Frames on a clock of the test's own: time moves only when the pacing waits or a frame
// computes. Inputs always waiting (a pose stream faster than the rate); each frame computes 5 ms
// but one, which computes `long_ms`. Returns the frames' start times (ms).
std::vector<double> input_frames_around_a_long_one(double long_ms) {
  Clock::time_point t{};
  FramePacing pacing(50, 50, {[&] { return t; }, [&](Clock::time_point u) { t = std::max(t, u); }});
  const FramePacing::WaitForInput input_waiting = [](Clock::time_point) { return true; };
  std::vector<double> starts;
  for (int frame = 0; frame < 30; ++frame) {
    pacing.until_next_frame(input_waiting);
    starts.push_back(std::chrono::duration<double, std::milli>(t.time_since_epoch()).count());
    t += std::chrono::microseconds(static_cast<int64_t>(1e3 * (frame == 10 ? long_ms : 5.0)));
  }
  return starts;
}

TEST(FramePacing, ALateInputFrameKeepsItsSlot) {
  // 50 Hz (20 ms), the frames on a grid, each half a period before it is due. Frame 10 computes
  // 45 ms: frame 11 starts 15 ms after it was due; frames 11 and 12 then run back to back and
  // frame 13 is on the grid again (60 ms after frame 10). Without the catch-up every later frame
  // starts 5 ms late (mutation tried: killed).
  const std::vector<double> starts = input_frames_around_a_long_one(45);
  for (int frame = 2; frame < 10; ++frame) EXPECT_DOUBLE_EQ(starts[frame] - starts[frame - 1], 20) << frame;
  EXPECT_DOUBLE_EQ(starts[11] - starts[10], 45);
  EXPECT_DOUBLE_EQ(starts[12] - starts[11], 5) << "back to back: the slot the long frame took";
  for (int frame = 13; frame < 30; ++frame) EXPECT_DOUBLE_EQ(starts[frame] - starts[10], 20 * (frame - 10)) << frame;
}

TEST(FramePacing, OnlyThreePeriodsAreMadeUp) {
  // Frame 10 computes 100 ms (five periods): three periods of its lateness are made up, frames
  // 11-15 back to back, and the rest lost, frame 16 on a grid 10 ms later than the first (a
  // frame held up for long, e.g. by the machine, does not start a burst of frames for long); in
  // any window of W periods at most W + 4.5 frames start (the half period early and the three
  // periods made up). Mutations tried, one and five periods made up: killed.
  const std::vector<double> starts = input_frames_around_a_long_one(100);
  EXPECT_DOUBLE_EQ(starts[11] - starts[10], 100);
  for (int frame = 12; frame <= 15; ++frame) EXPECT_DOUBLE_EQ(starts[frame] - starts[frame - 1], 5) << frame;
  for (int frame = 16; frame < 30; ++frame) EXPECT_DOUBLE_EQ(starts[frame] - starts[10], 20 * (frame - 10) + 10) << frame;
  const double window = 200;  // ms, 10 periods
  for (size_t first = 0; first < starts.size(); ++first) {
    const auto end = std::upper_bound(starts.begin(), starts.end(), starts[first] + window - 1e-9);
    EXPECT_LE(end - (starts.begin() + first), 14) << "frames within 10 periods from frame " << first;
  }
}

}  // namespace
}  // namespace liver_sim
