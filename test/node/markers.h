// Shared by the node's marker tests.
#pragma once

#include <visualization_msgs/Marker.h>

#include <Eigen/Core>

namespace liver_sim {

// Where a marker is: its pose's origin.
inline Eigen::Vector3d position(const visualization_msgs::Marker& m) {
  return Eigen::Vector3d(m.pose.position.x, m.pose.position.y, m.pose.position.z);
}

}  // namespace liver_sim
