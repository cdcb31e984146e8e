// The node on its default OR scene, the vascularised liver phantom (rostest
// test/phantom_node.test): the published surface and vessels against the core model solved
// here, a probe pressed onto the sagged right lobe, and ~status's heartbeat during long frames.
#include <geometry_msgs/PoseStamped.h>
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <visualization_msgs/Marker.h>

#include <cmath>
#include <functional>

#include "liver_sim/SimulationStatus.h"
#include "liver_sim/simulation/liver_model.h"
#include "wait_for.h"

namespace {

using liver_sim_test::wait_for;

liver_sim::SimulationStatus status;
visualization_msgs::Marker mesh, vessels;
int status_count = 0, mesh_count = 0, vessel_count = 0;
// Heartbeats ("busy": a long frame in progress and no status for one frame) that did not repeat the status before them.
int busy_count = 0, busy_not_a_repeat = 0;

void on_status(const liver_sim::SimulationStatus::ConstPtr& m) {
  if (m->state == "busy") {
    ++busy_count;
    busy_not_a_repeat += status_count > 0 && (m->step != status.step || m->max_displacement != status.max_displacement);
  }
  status = *m;
  ++status_count;
}

TEST(PhantomNode, PublishesTheEquilibriumOfTheCoreModelWithVessels) {
  ros::NodeHandle nh;
  using StatusPtr = liver_sim::SimulationStatus::ConstPtr;
  using MarkerPtr = visualization_msgs::Marker::ConstPtr;
  auto s1 = nh.subscribe<liver_sim::SimulationStatus>("liver_sim/status", 100, boost::function<void(const StatusPtr&)>(on_status));
  auto s2 = nh.subscribe<visualization_msgs::Marker>(
      "liver_sim/mesh", 2, boost::function<void(const MarkerPtr&)>([](const MarkerPtr& m) { mesh = *m, ++mesh_count; }));
  auto s3 = nh.subscribe<visualization_msgs::Marker>(
      "liver_sim/vessels", 2, boost::function<void(const MarkerPtr&)>([](const MarkerPtr& m) { vessels = *m, ++vessel_count; }));
  ros::Publisher pose_pub = nh.advertise<geometry_msgs::PoseStamped>("instruments/tool/pose", 1);

  // The same scene solved by the core, independently of the node.
  const liver_sim::Scene scene = liver_sim::load_scene(std::string(LIVER_SIM_SOURCE_DIR) + "/config/scenes/liver_phantom.yaml");
  liver_sim::LiverModel model(liver_sim::load_scene_mesh(scene), scene);
  ASSERT_TRUE(model.step().converged());
  ASSERT_GE(model.mesh().T.rows(), 10000);
  ASSERT_GT(model.num_beams(), 100);

  ASSERT_TRUE(wait_for([] { return status_count > 0 && status.state == "idle" && vessel_count > 0 && mesh_count > 0; }, 60.0))
      << "no idle status, mesh and vessels from the node";
  EXPECT_NEAR(status.max_displacement, model.max_displacement(), 1e-6 * model.max_displacement());
  ASSERT_EQ(vessels.type, visualization_msgs::Marker::LINE_LIST);
  ASSERT_EQ(vessels.points.size(), 2u * model.num_beams());
  double worst = 0;
  for (int e = 0; e < model.num_beams(); ++e)
    for (int end = 0; end < 2; ++end) {
      const auto& p = vessels.points[2 * e + end];
      const Eigen::Vector3d q = model.vessel_node_position(model.beam_segments()(e, end));
      worst = std::max(worst, (Eigen::Vector3d(p.x, p.y, p.z) - q).norm());
    }
  EXPECT_LE(worst, 1e-6) << "vessel marker differs from the core's vessel positions (m)";
  EXPECT_EQ(mesh.points.size(), 3u * model.boundary().rows());
  EXPECT_EQ(mesh.colors[0].a, 1.0f) << "the launch's surface_alpha draws an opaque surface";

  // A probe pressed 5 mm into the sagged right lobe above the tumour.
  const double before = status.max_displacement;
  geometry_msgs::PoseStamped pose;
  pose.header.frame_id = "liver";
  pose.pose.position.x = -0.05;
  pose.pose.position.y = -0.02;
  pose.pose.position.z = 0.039 + 0.0025 - 0.005;  // the launch's 2.5 mm probe radius
  pose.pose.orientation.w = 1;
  ASSERT_TRUE(wait_for([&] { return pose_pub.getNumSubscribers() > 0; }, 10.0));
  const ros::Time sent = ros::Time::now();
  pose.header.stamp = sent;
  pose_pub.publish(pose);
  // A tracker streams its poses (a pose older than the launch's ~pose_timeout withdraws the
  // instrument); the same pose re-sent costs the node nothing.
  const ros::WallTimer tracker = nh.createWallTimer(ros::WallDuration(0.1), [&](const ros::WallTimerEvent&) {
    pose.header.stamp = ros::Time::now();
    pose_pub.publish(pose);
  });
  EXPECT_TRUE(wait_for([&] { return status.header.stamp > sent + ros::Duration(0.2) && status.state == "idle"; }, 60.0));
  EXPECT_GT(status.active_contacts, 0);
  EXPECT_NE(status.max_displacement, before);
  EXPECT_TRUE(std::isfinite(status.max_displacement));
  // The phantom's factorisations take about a frame: the first step and the first contact
  // frames run longer, and ~status keeps its rate with the last step's status, never an older
  // one (a heartbeat sent outside the loop's publishing lock did, found by the soak).
  EXPECT_EQ(busy_not_a_repeat, 0) << "of " << busy_count << " busy statuses";
  RecordProperty("busy_statuses", busy_count);
}

}  // namespace

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "phantom_node_test");
  return RUN_ALL_TESTS();
}
