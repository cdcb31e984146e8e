// liver_sim_node: hosts a tracking session (tracking_session.h) in an OR guidance stack. The
// bridges turn messages into the session's inputs on the callbacks' threads (they only check,
// convert and submit the latest); the simulation thread runs the frames: the session applies the
// inputs and steps, the publishers say what it did.
#pragma once

#include <ros/ros.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/static_transform_broadcaster.h>
#include <tf2_ros/transform_listener.h>

#include <memory>

#include "cloud_bridge.h"
#include "frame_pacing.h"
#include "instrument_bridge.h"
#include "liver_sim/session/tracking_session.h"
#include "node_options.h"
#include "reconfigure_bridge.h"
#include "scene_publisher.h"
#include "services.h"
#include "status_publisher.h"

namespace liver_sim {

class LiverSimNode {
 public:
  // Builds the session from ~scene and the bridges; throws std::invalid_argument naming the
  // problem.
  LiverSimNode(ros::NodeHandle& nh, ros::NodeHandle& pnh, const NodeOptions& options);

  void start_heartbeat() { status_->start_heartbeat(); }
  // The loop, until ROS shuts down: a fault its frame's own guards did not catch (publishing,
  // diagnostics) is counted, and the loop goes on.
  void run();

 private:
  void frame();
  void publish_status(const StepResult& r);
  void fault(const std::string& text);
  // ~parent_frame and ~parent_transform put the model frame in the OR's tf tree (a static
  // transform), so that rviz and the OR's tools agree on where it is.
  void place_in_tf_tree();

  NodeOptions options_;
  tf2_ros::Buffer tf_buffer_;
  tf2_ros::TransformListener tf_listener_;
  tf2_ros::StaticTransformBroadcaster static_broadcaster_;
  std::unique_ptr<TrackingSession> session_;
  std::unique_ptr<InstrumentBridge> instruments_;
  std::unique_ptr<CloudBridge> clouds_;
  std::unique_ptr<ScenePublisher> scene_;
  std::unique_ptr<StatusPublisher> status_;
  std::unique_ptr<ReconfigureBridge> reconfigure_;
  std::unique_ptr<Services> services_;
  FramePacing pacing_;
};

}  // namespace liver_sim
