// What the node says of itself: ~status after each step (and at the publishing rate while idle),
// a heartbeat that keeps ~status at the frame rate while a long frame runs, and the diagnostics.
#pragma once

#include <diagnostic_updater/diagnostic_updater.h>
#include <ros/ros.h>

#include <atomic>
#include <deque>
#include <functional>
#include <mutex>
#include <string>
#include <thread>

#include "cloud_bridge.h"
#include "liver_sim/SimulationStatus.h"
#include "liver_sim/session/tracking_session.h"

namespace liver_sim {

// The state a heartbeat's status says: a frame in progress.
constexpr const char* kBusyWord = "busy";

class StatusPublisher {
 public:
  StatusPublisher(ros::NodeHandle& nh, ros::NodeHandle& pnh, TrackingSession& session,
                  std::function<CloudBridge::Counts()> clouds, const std::string& frame_id);
  ~StatusPublisher();

  // The heartbeat's thread of its own, which neither message callbacks nor roscpp's timer thread
  // can delay. Called from the thread that starts the callbacks' spinner (its processors and
  // priority).
  void start_heartbeat();
  // Simulation thread: a frame starts and ends (the heartbeat covers a long one).
  void frame_started();
  void frame_ended();
  void note_step();  // a step ran now (a status's rate counts the steps of the last second)
  // The status of the step `r` and the session as it is now, `rate` the loop's (Hz). Returns its
  // header (the wrenches and tip frames share it).
  std_msgs::Header publish(const StepResult& r, double rate);
  void update_diagnostics() { updater_.update(); }

 private:
  void heartbeat();
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& stat);
  double largest_radius_95() const;  // m, of the targets' 95% ellipsoids; 0 before an analysis

  TrackingSession& session_;
  std::function<CloudBridge::Counts()> clouds_;
  std::string frame_id_;
  ros::Publisher status_pub_;
  diagnostic_updater::Updater updater_;
  std::deque<ros::WallTime> step_times_;  // of the steps in the last second (simulation thread)

  // Shared with the heartbeat, under status_mutex_.
  std::mutex status_mutex_;
  SimulationStatus last_status_;  // as last published by the loop
  ros::WallTime last_status_time_, frame_start_;  // frame_start_: zero between frames
  double frame_period_ = 1.0 / 30;  // s, at the last status
  std::thread heartbeat_;
  std::atomic<bool> stop_heartbeat_{false};
};

}  // namespace liver_sim
