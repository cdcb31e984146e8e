// When the node's frames start and when it publishes, in one place. A frame starts as soon as
// an input arrives (a pose, a cloud, a command), so that a pose's latency is the frame's
// compute, but frames at most ~rate a second on average (a faster stream is sampled: the
// latest of each input wins). Without input a frame starts one period of ~rate after the last one (one and
// a half after one an input started): a step still converging goes on, tf-driven instruments
// are read, stale ones noticed. The mesh
// goes out after the frames that moved it, at most ~publish_rate a second on average (paced as
// the input frames, a mesh up to half a period early); an idle status at most as often.
#pragma once

#include <chrono>
#include <functional>

namespace liver_sim {

class FramePacing {
 public:
  using Clock = std::chrono::steady_clock;
  // Waits until an input arrives (true) or the deadline (false).
  using WaitForInput = std::function<bool(Clock::time_point)>;

  FramePacing(double rate, double publish_rate);
  // From the next frame on (Hz).
  void set_rates(double rate, double publish_rate);
  double rate() const { return rate_; }
  // Until the next frame may start (see above); returns whether an input starts it.
  bool until_next_frame(const WaitForInput& wait_for_input);
  // Whether the mesh may go out now; mesh_sent() takes the slot.
  bool mesh_due() const;
  void mesh_sent();
  // Whether an idle status is due now; when it is, the next is a publishing period later.
  bool idle_status_due();

 private:
  Clock::duration period(double hz) const;
  double rate_, publish_rate_;
  Clock::time_point last_start_, last_input_start_;
  Clock::time_point frame_due_;  // when the next frame is due at the rate
  Clock::time_point mesh_due_, next_idle_status_;
};

}  // namespace liver_sim
