// Live tuning through dynamic_reconfigure (cfg/LiverSim.cfg): the solver's strategy, iterations
// and tolerance, friction, the registration's stiffness and the instruments' staleness go to the
// session (all of them, or none when it refuses one); the rates and the display settings are the
// node's own and change with them. The server shows the values in force after a refusal.
#pragma once

#include <dynamic_reconfigure/server.h>
#include <ros/ros.h>

#include <boost/thread/recursive_mutex.hpp>
#include <memory>
#include <mutex>
#include <optional>

#include "liver_sim/LiverSimConfig.h"
#include "liver_sim/session/tracking_session.h"
#include "node_options.h"

namespace liver_sim {

class ReconfigureBridge {
 public:
  // Starts the server from the node's values, clamped to the config's bounds (and said).
  ReconfigureBridge(ros::NodeHandle& pnh, TrackingSession& session, const NodeOptions& options);

  // Simulation thread, before the session's frame: the latest change, the node's own values
  // checked, handed to the session.
  void before_frame();
  // After it: the change as the node takes it (its rates and display), when the session took
  // its part.
  std::optional<LiverSimConfig> after_frame(const FrameReport& report);

 private:
  LiverSimConfig current() const;  // the values in force

  TrackingSession& session_;
  bool budget_follows_rate_;
  LiverSimConfig node_values_;  // rate, publish_rate, color_scale_max, surface_alpha in force
  boost::recursive_mutex server_mutex_;
  std::unique_ptr<dynamic_reconfigure::Server<LiverSimConfig>> server_;
  std::mutex mutex_;
  std::optional<LiverSimConfig> pending_;    // from the server's callback, under mutex_
  std::optional<LiverSimConfig> submitted_;  // simulation thread
};

}  // namespace liver_sim
