#include "scene_publisher.h"

#include <geometry_msgs/PoseArray.h>
#include <visualization_msgs/MarkerArray.h>

#include <algorithm>

#include "liver_sim/TargetCovariances.h"
#include "mesh_marker.h"
#include "msg_conversion.h"

namespace liver_sim {

ScenePublisher::ScenePublisher(ros::NodeHandle& pnh, const TrackingSession& session, const std::string& frame_id,
                               double color_scale_max, double surface_alpha)
    : session_(session), frame_id_(frame_id), color_scale_max_(color_scale_max), surface_alpha_(surface_alpha) {
  mesh_pub_ = pnh.advertise<visualization_msgs::Marker>("mesh", 1, true);
  vessel_pub_ = pnh.advertise<visualization_msgs::Marker>("vessels", 1, true);
  target_marker_pub_ = pnh.advertise<visualization_msgs::MarkerArray>("targets", 1, true);
  target_pose_pub_ = pnh.advertise<geometry_msgs::PoseArray>("target_poses", 1, true);
  covariance_pub_ = pnh.advertise<TargetCovariances>("target_covariances", 1, true);
  ellipsoid_pub_ = pnh.advertise<visualization_msgs::MarkerArray>("target_ellipsoids", 1, true);
}

void ScenePublisher::set_display(double color_scale_max, double surface_alpha) {
  display_due_ |= color_scale_max_ != color_scale_max || surface_alpha_ != surface_alpha;
  color_scale_max_ = color_scale_max;
  surface_alpha_ = surface_alpha;
}

void ScenePublisher::note(const FrameReport& report) {
  if (report.reset) reference_.resize(0);
  display_due_ |= report.analysis.adopted;
}

bool ScenePublisher::publish() {
  const LiverModel& model = session_.model();
  // Displacements from the pre-operative equilibrium: the first converged state after start or
  // reset; taking it recolours the mesh.
  if (reference_.size() == 0 && session_.last_step().converged()) {
    reference_ = model.positions();
    display_due_ = true;
  }
  if (!display_due_ && published_positions_.size() == model.positions().size() && published_positions_ == model.positions())
    return false;
  published_positions_ = model.positions();
  display_due_ = false;
  marker_.header.frame_id = frame_id_;
  // The stamp of the input the shape reflects, so that latency can be measured.
  marker_.header.stamp = session_.reflected_stamp() == 0 ? ros::Time::now() : to_time(session_.reflected_stamp());
  marker_.ns = "liver";
  marker_.id = 0;
  fill_mesh_marker(model, reference_.size() ? reference_ : model.positions(), color_scale_max_, surface_alpha_, marker_);
  mesh_pub_.publish(marker_);
  publish_targets(marker_.header);
  if (model.num_beams() > 0) {
    vessel_marker_.header = marker_.header;
    vessel_marker_.ns = "vessels";
    fill_vessel_marker(model, vessel_marker_);
    vessel_pub_.publish(vessel_marker_);
  }
  return true;
}

// The tumour probes and vessel bifurcations where the model has them now: spheres (tumour red,
// bifurcations blue; namespace "probes" or "bifurcations", id = the target's index, as in the
// poses) and their poses (orientation: identity); their names in markers of their own (rviz flags
// text on a sphere), off the organ with leader lines, the patient's axes and the colour legend
// (append_annotations); with an analysis, their covariances and 95% ellipsoids.
void ScenePublisher::publish_targets(const std_msgs::Header& header) {
  const LiverModel& model = session_.model();
  const std::vector<TrackedTarget> targets = tracked_targets(model);
  visualization_msgs::MarkerArray markers;
  geometry_msgs::PoseArray poses;
  poses.header = header;
  for (size_t i = 0; i < targets.size(); ++i) {
    visualization_msgs::Marker m;
    m.header = header;
    const bool vessel = targets[i].kind == TrackedTarget::Kind::Bifurcation;
    m.ns = vessel ? "bifurcations" : "probes";
    m.id = static_cast<int>(i);
    m.type = visualization_msgs::Marker::SPHERE;
    m.action = visualization_msgs::Marker::ADD;
    m.pose = to_pose(Eigen::Isometry3d(Eigen::Translation3d(targets[i].position)));
    m.scale.x = m.scale.y = m.scale.z = vessel ? 0.004 : 0.003;
    m.color.r = vessel ? 0.2f : 1.0f;
    m.color.g = 0.2f;
    m.color.b = vessel ? 1.0f : 0.2f;
    m.color.a = 1.0f;
    markers.markers.push_back(m);
    poses.poses.push_back(m.pose);
  }
  const Eigen::MatrixX3d& rest = model.mesh().V;
  const Eigen::AlignedBox3d box(rest.colwise().minCoeff().transpose(), rest.colwise().maxCoeff().transpose());
  append_annotations(targets, model.positions(), box, color_scale_max_, header, markers);
  target_marker_pub_.publish(markers);
  target_pose_pub_.publish(poses);
  const std::vector<TargetUncertainty::Covariance>& covariances = session_.covariances();
  if (covariances.size() != targets.size()) return;  // no analysis since the last reset
  TargetCovariances covariance;
  covariance.header = header;
  covariance.analysis_stamp = to_time(session_.analysis_stamp());
  visualization_msgs::MarkerArray ellipsoids;
  for (size_t i = 0; i < targets.size(); ++i) {
    covariance.names.push_back(targets[i].name);
    geometry_msgs::PoseWithCovariance p;
    p.pose = poses.poses[i];
    for (int a = 0; a < 3; ++a) {
      for (int b = 0; b < 3; ++b) p.covariance[6 * a + b] = covariances[i].total(a, b);
      p.covariance[6 * (a + 3) + a + 3] = 1e6;  // the rotations are unknown
    }
    covariance.poses.push_back(p);
    // The 95% ellipsoid: a sphere scaled along the covariance's eigenvectors.
    const Ellipsoid e = ellipsoid_95(covariances[i].total);
    visualization_msgs::Marker m = markers.markers[i];
    m.ns = markers.markers[i].ns + "_95";
    m.pose.orientation = to_quaternion(e.axes);
    m.scale.x = std::max(2 * e.semi_axes.x(), 1e-4);  // rviz draws no zero-size marker
    m.scale.y = std::max(2 * e.semi_axes.y(), 1e-4);
    m.scale.z = std::max(2 * e.semi_axes.z(), 1e-4);
    m.color.a = 0.3f;
    ellipsoids.markers.push_back(m);
  }
  covariance_pub_.publish(covariance);
  ellipsoid_pub_.publish(ellipsoids);
}

}  // namespace liver_sim
