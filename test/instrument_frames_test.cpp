// rostest test/instrument_frames.test: an instrument tracked through tf (~instrument_frames).
#include <geometry_msgs/WrenchStamped.h>
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <tf2_ros/transform_broadcaster.h>

#include "liver_sim/SimulationStatus.h"

namespace {

liver_sim::SimulationStatus status;
geometry_msgs::WrenchStamped wrench;

TEST(InstrumentFrames, ToolFramePressesTheTissue) {
  ros::NodeHandle nh;
  ros::Subscriber s = nh.subscribe<liver_sim::SimulationStatus>(
      "liver_sim/status", 10, boost::function<void(const liver_sim::SimulationStatus::ConstPtr&)>(
                                  [](const liver_sim::SimulationStatus::ConstPtr& m) { status = *m; }));
  ros::Subscriber w = nh.subscribe<geometry_msgs::WrenchStamped>(
      "liver_sim/wrench", 10, boost::function<void(const geometry_msgs::WrenchStamped::ConstPtr&)>(
                                  [](const geometry_msgs::WrenchStamped::ConstPtr& m) { wrench = *m; }));
  tf2_ros::TransformBroadcaster broadcaster;
  // The tool tip 2 mm into the top face near a corner (tip radius 3 mm), sent at 20 Hz.
  geometry_msgs::TransformStamped tool;
  tool.header.frame_id = "liver";
  tool.child_frame_id = "tool_tip";
  tool.transform.translation.x = 0.0035;
  tool.transform.translation.y = 0.0035;
  tool.transform.translation.z = 0.015 + 0.003 - 0.002;
  tool.transform.rotation.w = 1.0;
  const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(20.0);
  while (ros::ok() && ros::WallTime::now() < end && !(status.active_contacts > 0 && status.state == "idle")) {
    tool.header.stamp = ros::Time::now();
    broadcaster.sendTransform(tool);
    ros::spinOnce();
    ros::WallDuration(0.05).sleep();
  }
  EXPECT_GT(status.active_contacts, 0) << "state " << status.state;
  EXPECT_GT(wrench.wrench.force.z, 0.0) << "the tissue pushes the tool up";
  EXPECT_EQ(status.rejected_inputs, 0u);
}

}  // namespace

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "instrument_frames_test");
  return RUN_ALL_TESTS();
}
