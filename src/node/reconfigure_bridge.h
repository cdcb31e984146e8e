// Live tuning through dynamic_reconfigure (cfg/LiverSim.cfg): the solver's strategy, iterations
// and tolerance, friction, the registration's stiffness and the instruments' staleness go to the
// session (all of them, or none when it refuses one); the rates and the display settings are the
// node's own and change with them. A value outside the config's bounds is clamped to them and
// said (log and ~status), naming the value asked: the bridge serves dynamic_reconfigure's service
// and topics itself, as dynamic_reconfigure::Server clamps before its callback sees the request.
// The values in force are shown again after a refusal.
#pragma once

#include <dynamic_reconfigure/Reconfigure.h>
#include <ros/ros.h>

#include <mutex>
#include <optional>

#include "liver_sim/LiverSimConfig.h"
#include "liver_sim/session/tracking_session.h"
#include "node_options.h"

namespace liver_sim {

class ReconfigureBridge {
 public:
  // Serves ~set_parameters, ~parameter_descriptions and ~parameter_updates, from the node's values
  // clamped to the config's bounds (and said).
  ReconfigureBridge(ros::NodeHandle& pnh, TrackingSession& session, const NodeOptions& options);

  // Simulation thread, before the session's frame: the latest change, the node's own values
  // checked, handed to the session.
  void before_frame();
  // After it: the change as the node takes it (its rates and display), when the session took
  // its part.
  std::optional<LiverSimConfig> after_frame(const FrameReport& report);

 private:
  LiverSimConfig current() const;  // the values in force
  bool on_set(dynamic_reconfigure::Reconfigure::Request& req, dynamic_reconfigure::Reconfigure::Response& res);
  // `asked` clamped to the config's bounds, each value clamped told to the session's notices.
  LiverSimConfig clamped(const LiverSimConfig& asked, const std::string& when);
  void show(const LiverSimConfig& c);  // on ~parameter_updates (and the parameter server)

  ros::NodeHandle pnh_;
  TrackingSession& session_;
  bool budget_follows_rate_;
  LiverSimConfig node_values_;  // rate, publish_rate, color_scale_max, surface_alpha in force
  ros::ServiceServer set_service_;
  ros::Publisher descriptions_pub_, updates_pub_;
  std::mutex mutex_;
  LiverSimConfig shown_;                     // the values last shown, under mutex_
  std::optional<LiverSimConfig> pending_;    // from the service, under mutex_
  std::optional<LiverSimConfig> submitted_;  // simulation thread
};

}  // namespace liver_sim
