// rostest test/instrument_tf_late.test: trackers start in any order. A probe declared with a tf
// frame that does not exist yet is accepted, waits out of the scene (said in ~status) and joins
// at the first frame after the frame's first broadcast. Frames are counted by the node's own
// steps: the default rod `tool` is moved every 50 ms, so that every 0.2 s frame steps and
// reports its step; after the broadcast at most one step (the frame in progress when it came)
// may leave the probe out. (With the old behaviour, a refusal, the probe never joins.)
#include <geometry_msgs/PoseStamped.h>
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <tf2_ros/transform_broadcaster.h>

#include <algorithm>
#include <set>
#include <vector>

#include "liver_sim/InstrumentCommand.h"
#include "liver_sim/SimulationStatus.h"
#include "wait_for.h"

namespace {

using liver_sim_test::wait_for;

std::vector<liver_sim::SimulationStatus> statuses;

bool has(const liver_sim::SimulationStatus& s, const std::string& name) {
  return std::find(s.instrument_names.begin(), s.instrument_names.end(), name) != s.instrument_names.end();
}

TEST(InstrumentTfLate, ProbeDeclaredBeforeItsFrameJoinsWithinOneFrame) {
  ros::NodeHandle nh;
  ros::Subscriber sub = nh.subscribe<liver_sim::SimulationStatus>(
      "liver_sim/status", 100, boost::function<void(const liver_sim::SimulationStatus::ConstPtr&)>(
                                   [](const liver_sim::SimulationStatus::ConstPtr& m) { statuses.push_back(*m); }));
  ros::Publisher command = nh.advertise<liver_sim::InstrumentCommand>("instrument_command", 1, true);
  ros::Publisher tool = nh.advertise<geometry_msgs::PoseStamped>("instruments/tool/pose", 10);
  ASSERT_TRUE(wait_for([&] { return !statuses.empty() && command.getNumSubscribers() > 0 && tool.getNumSubscribers() > 0; }, 30.0));

  liver_sim::InstrumentCommand declare;
  declare.name = "ball";
  declare.type = "probe";
  declare.radius = 0.003;
  declare.frame = "probe_tip";
  command.publish(declare);
  ASSERT_TRUE(wait_for([] { return statuses.back().text.find("probe_tip") != std::string::npos; }, 10.0))
      << "no status says that ball waits for its frame";
  const liver_sim::SimulationStatus waiting = statuses.back();
  EXPECT_EQ(waiting.rejected_inputs, 0u) << waiting.text;
  EXPECT_FALSE(has(waiting, "ball"));

  // The rod hovers above the cube (15 mm high), moving 0.1 mm every 50 ms: a step every frame.
  geometry_msgs::PoseStamped pose;
  pose.header.frame_id = "liver";
  pose.pose.position.x = 0.0075;
  pose.pose.position.y = 0.0075;
  pose.pose.orientation.w = 1.0;
  int moves = 0;
  auto move_tool = [&] {
    pose.header.stamp = ros::Time::now();
    pose.pose.position.z = 0.03 + 1e-4 * (moves++ % 20);
    tool.publish(pose);
  };
  // Three frames in a row stepping before the frame appears.
  const ros::WallTime stepping = ros::WallTime::now() + ros::WallDuration(30.0);
  while (ros::ok() && ros::WallTime::now() < stepping) {
    move_tool();
    ros::WallDuration(0.05).sleep();
    ros::spinOnce();
    std::set<uint64_t> recent;
    for (const auto& s : statuses)
      if (s.header.stamp > ros::Time::now() - ros::Duration(0.7)) recent.insert(s.step);
    if (recent.size() >= 3) break;
  }
  ASSERT_FALSE(has(statuses.back(), "ball"));

  tf2_ros::TransformBroadcaster broadcaster;
  geometry_msgs::TransformStamped frame;
  frame.header.frame_id = "liver";
  frame.child_frame_id = "probe_tip";
  frame.transform.translation.x = 0.0075;
  frame.transform.translation.y = 0.0075;
  frame.transform.translation.z = 0.05;  // above the cube: the test is about joining, not contact
  frame.transform.rotation.w = 1.0;
  const ros::Time first_broadcast = ros::Time::now();
  const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(20.0);
  while (ros::ok() && ros::WallTime::now() < end && !has(statuses.back(), "ball")) {
    frame.header.stamp = ros::Time::now();
    broadcaster.sendTransform(frame);
    move_tool();
    ros::WallDuration(0.05).sleep();
    ros::spinOnce();
  }
  ASSERT_TRUE(has(statuses.back(), "ball")) << "the probe never joined: " << statuses.back().text;
  std::set<uint64_t> steps_without;  // steps that ended after the first broadcast, the probe out
  for (const auto& s : statuses)
    if (s.header.stamp > first_broadcast && !has(s, "ball") && s.state != "busy") steps_without.insert(s.step);
  EXPECT_LE(steps_without.size(), 1u) << "steps after the frame's first broadcast without the probe";
  EXPECT_EQ(statuses.back().text.find("waiting for tf"), std::string::npos) << statuses.back().text;
  EXPECT_EQ(statuses.back().rejected_inputs, 0u);
}

}  // namespace

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "instrument_tf_late_test");
  return RUN_ALL_TESTS();
}
