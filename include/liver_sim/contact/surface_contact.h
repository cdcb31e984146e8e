// A contact between an instrument and a material point of the surface, ROS-free: where, with
// what force, and its rows (the gap and the slips, or for a held point the position error).
#pragma once

#include <Eigen/Core>

#include "liver_sim/contact/instrument_slot.h"
#include "liver_sim/contact/surface_point.h"

namespace liver_sim {

struct SurfaceContact {
  int instrument;
  SurfacePoint point;
  int held;               // bilateral: its index in the grasper's held points; -1: unilateral
  Eigen::Matrix3d frame;  // columns: normal, tangent, tangent (bilateral: identity), at the last detection
  Eigen::Vector3d rows;   // gap and slips there (m)
  Eigen::Vector3d lambda; // N on the tissue at the point, in the frame (normal first)
};

// Normal gap and tangential slips (bilateral: position error) of contact c of instrument `in`
// at x (m), slips measured from x_stage, the positions at the start of the stage; and its frame
// (columns: normal, tangents).
Eigen::Vector3d contact_rows(const SurfaceContact& c, const InstrumentSlot& in, const Eigen::VectorXd& x,
                             const Eigen::VectorXd& x_stage, Eigen::Matrix3d* frame);

}  // namespace liver_sim
