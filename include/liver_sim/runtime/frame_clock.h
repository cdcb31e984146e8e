// Real-time frames on a fixed grid of slots, one period apart (the node's loop, bench --paced).
// A frame that ends early waits for its slot. A late one starts the next frame at once, and the
// frames after it catch up with the grid while the loop is at most `catch_up` periods behind
// it: a frame that overran (on the phantom a factorisation takes about one 30 Hz frame) costs
// no slot as long as the frames take less than a period on average. Further behind (a step
// held up), the grid starts again where the late frame ended: the missed slots are dropped, not
// run in a burst. (ros::WallRate starts again once a frame ends a period behind its slot, which
// drops the time of every frame longer than two periods.) ROS-free.
#pragma once

#include <chrono>

namespace liver_sim {

class FrameClock {
 public:
  using Clock = std::chrono::steady_clock;
  // The real-time loops' (the node, bench --paced): a factorisation on the phantom makes a
  // frame one to two periods long; a step held up longer drops its slots.
  static constexpr int kCatchUp = 3;
  // Throws std::invalid_argument unless period is in [1e-6, 1e6] s and catch_up in [0, 1000].
  FrameClock(double period, int catch_up, Clock::time_point start = Clock::now());

  // When the next frame starts, for a frame that ended at `now`; moves the grid on by a slot.
  Clock::time_point next(Clock::time_point now);
  // Sleeps until next(Clock::now()).
  void sleep();
  // From the next slot on.
  void set_period(double period);

 private:
  Clock::duration period_;
  int catch_up_;
  Clock::time_point slot_;  // the start of the current frame's slot
};

}  // namespace liver_sim
