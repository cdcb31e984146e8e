// What a tracking session takes in, ROS-free: each a value the caller fills from its own
// messages (the node's msg_conversion.h), each kept as the latest of its kind until a frame
// applies it (tracking_session.h).
#pragma once

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <optional>
#include <string>

#include "liver_sim/scene/options.h"

namespace liver_sim {

// An input's stamp, carried to the outputs that reflect it: integer nanoseconds on the inputs'
// clock (ROS time; a bag's in playback), so that an output carries its input's stamp exactly.
// 0: none.
using Stamp = std::int64_t;
constexpr double kSecondsPerStamp = 1e-9;

// The clocks a frame runs on: `stamp`, the inputs' clock (pose staleness, the analysis's stamp);
// `wall`, a steady clock (s: the analysis's period).
struct FrameTime {
  Stamp stamp = 0;
  double wall = 0;
};

// Declares, changes or removes a named instrument (the fields of liver_sim/InstrumentCommand.msg).
struct InstrumentRequest {
  std::string name;   // 1 to 32 letters, digits or '_'
  std::string type;   // probe, shaft, tube or grasper: declares it (anew); empty: changes a declared one
  std::string frame;  // where its poses come from: empty its own pose stream, else a frame the
                      // caller looks up each frame (frame_poses()); a change keeps it unless named
  double radius = 0, length = 0, inner_radius = 0, outer_radius = 0;  // m; 0 keeps the value
  double suction = 0;  // Pa, tubes
  bool grasp = false;  // graspers: closed
  bool remove = false;
};

// The latest pose of an instrument posed from its own stream: its tip in the model frame.
struct InstrumentPose {
  std::string name;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();           // m
  Eigen::Quaterniond orientation = Eigen::Quaterniond::Identity();  // unit
  Stamp stamp = 0;     // the pose's own
  Stamp received = 0;  // when it came, on the frames' stamp clock (staleness counts from it)
};

// The transform of the frame that drives an instrument, looked up at the start of a frame.
struct FramePose {
  std::string name;   // the instrument
  std::string frame;  // the frame looked up (a pose of a frame the instrument left is ignored)
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  Stamp stamp = 0;    // the transform's; 0: a static frame, which never goes stale
};

// The latest point cloud, already in the model frame (cropped and downsampled by the caller,
// prepare_cloud).
struct Cloud {
  pcl::PointCloud<pcl::PointXYZ> points;
  std::optional<Eigen::Vector3d> viewpoint;  // the sensor's origin, model frame, when known
  Stamp stamp = 0;
};

// A capsule change: `enabled`, and each value, 0 keeping the one in force (or pending).
struct CapsuleEdit {
  bool enabled = true;
  double young_modulus = 0, thickness = 0, poisson_ratio = 0;  // Pa, m, -
};

// The options a running session may change: all of them apply, or none.
struct LiveOptions {
  SolverOptions::Strategy strategy = SolverOptions::Strategy::ModifiedNewton;
  int max_iterations = 2;
  double tolerance = 1e-6;
  std::optional<double> time_budget;  // s; none: kept
  double friction = 0;
  double registration_stiffness = 0;  // N/m
  double pose_timeout = 1.0;          // s, 0: never stale
  bool hold_stale = false;
};

// Back to the rest shape, or to `positions` (3 #V, m: a pre-operative state).
struct Reset {
  std::optional<Eigen::VectorXd> positions;
};

// The next cloud is rigidly aligned (ICP) before it is registered.
struct AlignRigidly {};

}  // namespace liver_sim
