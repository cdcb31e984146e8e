#include "msg_conversion.h"

#include <tf2_eigen/tf2_eigen.h>

#include <cmath>

namespace liver_sim {

Eigen::Isometry3d to_isometry(const geometry_msgs::Transform& t) {
  Eigen::Quaterniond q;
  Eigen::Vector3d v;
  tf2::fromMsg(t.rotation, q);
  tf2::fromMsg(t.translation, v);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = q.normalized().toRotationMatrix();
  T.translation() = v;
  return T;
}

std::string pose_error(geometry_msgs::Pose& p) {
  Eigen::Vector3d position;
  Eigen::Quaterniond q;
  tf2::fromMsg(p.position, position);
  tf2::fromMsg(p.orientation, q);
  if (!position.allFinite() || !q.coeffs().allFinite()) return "NaN or infinite values";
  // An orientation left at zeros (unset) is the identity: the instrument points up its frame's z.
  if (q.coeffs().isZero(0.0)) p.orientation.w = 1;
  tf2::fromMsg(p.orientation, q);
  if (!(std::abs(q.norm() - 1) < 1e-3)) return "orientation is not a unit quaternion";
  return "";
}

void to_position_orientation(const geometry_msgs::Pose& p, Eigen::Vector3d& position, Eigen::Quaterniond& orientation) {
  tf2::fromMsg(p.position, position);
  tf2::fromMsg(p.orientation, orientation);
  orientation.normalize();
}

geometry_msgs::Pose to_pose(const Eigen::Isometry3d& P) {
  geometry_msgs::Pose p;
  p.position = tf2::toMsg(Eigen::Vector3d(P.translation()));
  p.orientation = to_quaternion(P.linear());
  return p;
}

geometry_msgs::Quaternion to_quaternion(const Eigen::Matrix3d& rotation) {
  return tf2::toMsg(Eigen::Quaterniond(rotation));
}

geometry_msgs::Transform to_transform(const Eigen::Isometry3d& P) {
  geometry_msgs::Transform t;
  tf2::toMsg(Eigen::Vector3d(P.translation()), t.translation);
  t.rotation = tf2::toMsg(Eigen::Quaterniond(P.linear()));
  return t;
}

geometry_msgs::Vector3 to_vector(const Eigen::Vector3d& v) {
  geometry_msgs::Vector3 m;
  return tf2::toMsg(v, m);
}

Stamp to_stamp(const ros::Time& t) { return static_cast<Stamp>(t.toNSec()); }

ros::Time to_time(Stamp s) {
  ros::Time t;
  t.fromNSec(static_cast<uint64_t>(s));
  return t;
}

InstrumentRequest to_request(const InstrumentCommand& msg) {
  InstrumentRequest r;
  r.name = msg.name;
  r.type = msg.type;
  r.frame = msg.frame;
  r.radius = msg.radius;
  r.length = msg.length;
  r.inner_radius = msg.inner_radius;
  r.outer_radius = msg.outer_radius;
  r.suction = msg.suction;
  r.grasp = msg.grasp;
  r.remove = msg.remove;
  return r;
}

CapsuleEdit to_edit(const SetCapsule::Request& req) {
  CapsuleEdit e;
  e.enabled = req.enabled;
  e.young_modulus = req.young_modulus;
  e.thickness = req.thickness;
  e.poisson_ratio = req.poisson_ratio;
  return e;
}

void fill_response(const std::string& refusal, const CapsuleOptions& capsule, SetCapsule::Response& res) {
  res.success = refusal.empty();
  res.message = refusal.empty() ? "applied at the next step" : refusal;
  res.enabled = capsule.enabled;
  res.young_modulus = capsule.young_modulus;
  res.thickness = capsule.thickness;
  res.poisson_ratio = capsule.poisson_ratio;
}

LiveOptions to_live_options(const LiverSimConfig& c, SolverOptions::Strategy strategy, bool budget_follows_rate) {
  LiveOptions live;
  live.strategy = strategy;
  live.max_iterations = c.max_iterations;
  live.tolerance = c.tolerance;
  if (budget_follows_rate) live.time_budget = 1.0 / c.rate;
  live.friction = c.friction;
  live.registration_stiffness = c.registration_stiffness;
  live.pose_timeout = c.pose_timeout;
  live.hold_stale = c.hold_stale_instruments;
  return live;
}

void fill_config(const LiveOptions& live, LiverSimConfig& c) {
  c.strategy = strategy_word(live.strategy);
  c.max_iterations = live.max_iterations;
  c.tolerance = live.tolerance;
  c.friction = live.friction;
  c.registration_stiffness = live.registration_stiffness;
  c.pose_timeout = live.pose_timeout;
  c.hold_stale_instruments = live.hold_stale;
}

}  // namespace liver_sim
