// Shared by the rostest clients: spin until a condition holds.
#pragma once

#include <ros/ros.h>

#include <functional>

namespace liver_sim_test {

// Spins until pred holds or `seconds` of wall time pass; true when it held.
inline bool wait_for(const std::function<bool()>& pred, double seconds) {
  const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(seconds);
  while (ros::ok() && ros::WallTime::now() < end) {
    ros::spinOnce();
    if (pred()) return true;
    ros::WallDuration(0.01).sleep();
  }
  return false;
}

}  // namespace liver_sim_test
