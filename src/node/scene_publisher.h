// The scene as rviz and a guidance stack see it: the deformed surface (~mesh), the vessels
// (~vessels), the tracked targets (~targets, ~target_poses) and their uncertainty
// (~target_covariances, ~target_ellipsoids), sent when the shape, the display settings or the
// targets' uncertainty changed since they were last sent (latched: a late subscriber has them).
#pragma once

#include <ros/ros.h>
#include <visualization_msgs/Marker.h>

#include <Eigen/Core>
#include <string>

#include "liver_sim/session/tracking_session.h"

namespace liver_sim {

class ScenePublisher {
 public:
  ScenePublisher(ros::NodeHandle& pnh, const TrackingSession& session, const std::string& frame_id,
                 double color_scale_max, double surface_alpha);

  // The display settings (live); redrawn at the next publish() when they changed.
  void set_display(double color_scale_max, double surface_alpha);
  // What a frame did that changes the display: a reset (the displacements' reference is taken
  // anew), an analysis adopted (new covariances).
  void note(const FrameReport& report);
  // Sends what changed since the last time; false when nothing had.
  bool publish();

 private:
  void publish_targets(const std_msgs::Header& header);

  const TrackingSession& session_;
  std::string frame_id_;
  double color_scale_max_, surface_alpha_;
  ros::Publisher mesh_pub_, vessel_pub_, target_marker_pub_, target_pose_pub_, covariance_pub_, ellipsoid_pub_;
  visualization_msgs::Marker marker_, vessel_marker_;
  Eigen::VectorXd published_positions_;  // of the last mesh sent
  Eigen::VectorXd reference_;  // m, 3 #V: the pre-operative equilibrium; empty until known
  bool display_due_ = true;
};

}  // namespace liver_sim
