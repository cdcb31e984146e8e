// The one place where ROS messages and the core's types convert: geometry through tf2_eigen,
// stamps, the instrument and capsule requests, the live options. No state.
#pragma once

#include <geometry_msgs/Pose.h>
#include <geometry_msgs/Transform.h>
#include <geometry_msgs/Vector3.h>
#include <ros/time.h>

#include <Eigen/Geometry>
#include <string>

#include "liver_sim/InstrumentCommand.h"
#include "liver_sim/LiverSimConfig.h"
#include "liver_sim/SetCapsule.h"
#include "liver_sim/session/inputs.h"

namespace liver_sim {

// A transform as an isometry, its rotation normalised (a tracker's quaternion is unit to a few
// digits only).
Eigen::Isometry3d to_isometry(const geometry_msgs::Transform& t);
// Why a pose cannot be taken ("" when it can): a value not finite, an orientation not unit within
// 1e-3. An orientation of zeros (unset) becomes the identity.
std::string pose_error(geometry_msgs::Pose& p);
// A pose as a position and its orientation normalised.
void to_position_orientation(const geometry_msgs::Pose& p, Eigen::Vector3d& position, Eigen::Quaterniond& orientation);
geometry_msgs::Pose to_pose(const Eigen::Isometry3d& P);
geometry_msgs::Quaternion to_quaternion(const Eigen::Matrix3d& rotation);
geometry_msgs::Transform to_transform(const Eigen::Isometry3d& P);
geometry_msgs::Vector3 to_vector(const Eigen::Vector3d& v);

Stamp to_stamp(const ros::Time& t);
ros::Time to_time(Stamp s);

InstrumentRequest to_request(const InstrumentCommand& msg);
CapsuleEdit to_edit(const SetCapsule::Request& req);
void fill_response(const std::string& refusal, const CapsuleOptions& capsule, SetCapsule::Response& res);

// The live options of a reconfiguration (its strategy parsed beforehand); the time budget follows
// the rate when `budget_follows_rate`.
LiveOptions to_live_options(const LiverSimConfig& c, SolverOptions::Strategy strategy, bool budget_follows_rate);
// The options in force into a config (the node's own values already in `c`).
void fill_config(const LiveOptions& live, LiverSimConfig& c);

}  // namespace liver_sim
