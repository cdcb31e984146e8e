#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <stdexcept>

#include "liver_sim/runtime/frame_clock.h"

// The frame clock on made-up times (no wall clock): periods of 30 ms, catching up while at most
// two periods behind. Slots at 30, 60, 90, ... ms.
// Kills a grid that starts again as soon as a frame ends a period late (ros::WallRate's rule:
// the frame late by 1.5 periods would move the slots), one that never starts again (the held-up
// frame would be followed by a burst) and a late frame that waits for its slot (tried each).
TEST(FrameClock, LateFramesCatchUpWithTheGridAndAHoldUpDropsItsSlots) {
  using namespace std::chrono_literals;
  const liver_sim::FrameClock::Clock::time_point t0{};
  liver_sim::FrameClock clock(0.030, 2, t0);
  EXPECT_EQ(clock.next(t0 + 10ms), t0 + 30ms);   // early: waits for its slot
  EXPECT_EQ(clock.next(t0 + 105ms), t0 + 105ms);  // 45 ms late: at once
  EXPECT_EQ(clock.next(t0 + 115ms), t0 + 115ms);  // still 25 ms behind the slot at 90 ms
  EXPECT_EQ(clock.next(t0 + 119ms), t0 + 120ms);  // caught up: the grid as it was
  EXPECT_EQ(clock.next(t0 + 400ms), t0 + 400ms);  // held up 250 ms: at once,
  EXPECT_EQ(clock.next(t0 + 410ms), t0 + 430ms);  // and the slots start again from there
  clock.set_period(0.010);
  EXPECT_EQ(clock.next(t0 + 435ms), t0 + 440ms);
  EXPECT_THROW(liver_sim::FrameClock(0.0, 2), std::invalid_argument);
  EXPECT_THROW(liver_sim::FrameClock(0.03, -1), std::invalid_argument);
  EXPECT_THROW(liver_sim::FrameClock(std::nan(""), 2), std::invalid_argument);
}
