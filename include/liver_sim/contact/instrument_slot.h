// One instrument of the contact, ROS-free: its options and what the steps make of it (poses,
// the points it holds, its suction load, the reaction on it). A value: the stepper's rollback
// copies it whole.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <vector>

#include "liver_sim/contact/surface_point.h"
#include "liver_sim/scene/options.h"

namespace liver_sim {

struct InstrumentReaction {
  Eigen::Vector3d force = Eigen::Vector3d::Zero();   // N, exerted by the tissue on the instrument
  Eigen::Vector3d torque = Eigen::Vector3d::Zero();  // N m, about the instrument's tip
  int contacts = 0;                                  // surface points pressing on it or held by it
};

struct InstrumentSlot {
  InstrumentOptions options;
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();        // at the end of the step (stage)
  Eigen::Isometry3d pose_start = Eigen::Isometry3d::Identity();  // at its start
  bool closed = false;                       // grasper: its jaws, at the last step
  bool was_enabled = false;                  // at the last step
  std::vector<SurfacePoint> held;            // grasper: held points
  std::vector<Eigen::Vector3d> held_local;   // and where, in the grasper's frame
  int suction_load = -1;                     // its pressure load in the mechanical model (a tube's, kept by the slot)
  InstrumentReaction reaction;
};

}  // namespace liver_sim
