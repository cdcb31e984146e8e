// Integration test of liver_sim_node on a real ROS master (rostest test/liver_sim_node.test),
// on the aspiration cube (known equilibrium and geometry). The tests run in order and share the node.
#include <geometry_msgs/PoseStamped.h>
#include <geometry_msgs/WrenchStamped.h>
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <sensor_msgs/PointCloud2.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <std_srvs/Trigger.h>
#include <tf2_ros/static_transform_broadcaster.h>
#include <tf2_ros/transform_listener.h>
#include <visualization_msgs/Marker.h>

#include <Eigen/Core>
#include <cmath>
#include <functional>

#include "liver_sim/SetCapsule.h"
#include "liver_sim/SimulationStatus.h"
#include "wait_for.h"

namespace {

using liver_sim_test::wait_for;

class Node : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    nh_ = std::make_unique<ros::NodeHandle>();
    status_sub_ = nh_->subscribe("liver_sim/status", 10, &Node::on_status);
    wrench_sub_ = nh_->subscribe("liver_sim/wrench", 10, &Node::on_wrench);
    mesh_sub_ = nh_->subscribe("liver_sim/mesh", 10, &Node::on_mesh);
    pose_pub_ = nh_->advertise<geometry_msgs::PoseStamped>("instruments/tool/pose", 1);
    // A camera frame 10 cm along x from the model frame, for poses sent in another frame.
    tf_broadcaster_ = std::make_unique<tf2_ros::StaticTransformBroadcaster>();
    geometry_msgs::TransformStamped camera;
    camera.header.stamp = ros::Time::now();
    camera.header.frame_id = "liver";
    camera.child_frame_id = "camera";
    camera.transform.translation.x = 0.1;
    camera.transform.rotation.w = 1.0;
    tf_broadcaster_->sendTransform(camera);
    cloud_pub_ = nh_->advertise<sensor_msgs::PointCloud2>("points", 1);
    ASSERT_TRUE(wait_for([] { return status_count_ > 0 && mesh_count_ > 0 && pose_pub_.getNumSubscribers() > 0; }, 30.0))
        << "no status or mesh from liver_sim";
  }
  static void TearDownTestSuite() {
    // Before roscpp shuts down at exit: static handles destroyed after it read freed memory.
    status_sub_ = wrench_sub_ = mesh_sub_ = ros::Subscriber();
    pose_pub_ = cloud_pub_ = ros::Publisher();
    tf_broadcaster_.reset();
    nh_.reset();
  }
  static void on_status(const liver_sim::SimulationStatus::ConstPtr& m) {
    status_ = *m;
    ++status_count_;
  }
  static void on_wrench(const geometry_msgs::WrenchStamped::ConstPtr& m) { wrench_ = *m; }
  static void on_mesh(const visualization_msgs::Marker::ConstPtr& m) {
    mesh_ = *m;
    ++mesh_count_;
  }

  // Waits for the model to settle after an input sent at `sent`: an idle status stamped well
  // after it (one frame of the 30 Hz loop applies an input; statuses still queued from before
  // must not count).
  static liver_sim::SimulationStatus settled(ros::Time sent = ros::Time::now()) {
    const ros::Time after = sent + ros::Duration(0.15);
    // Generous: a 4 mm press takes about 2 s of solving here in Release, ten times that under
    // the sanitizers. The bound only ends a wait; it asserts no speed.
    EXPECT_TRUE(wait_for([&] { return status_.header.stamp > after && status_.state == "idle"; }, 90.0))
        << "state " << status_.state;
    return status_;
  }

  static void publish_pose(double x, double y, double z, const std::string& frame = "liver") {
    geometry_msgs::PoseStamped p;
    p.header.frame_id = frame;
    p.header.stamp = ros::Time::now();
    p.pose.position.x = x;
    p.pose.position.y = y;
    p.pose.position.z = z;
    p.pose.orientation.w = 1;
    pose_pub_.publish(p);
  }

  static liver_sim::SetCapsule::Response set_capsule(bool enabled, double E, double h, double nu) {
    liver_sim::SetCapsule srv;
    srv.request.enabled = enabled;
    srv.request.young_modulus = E;
    srv.request.thickness = h;
    srv.request.poisson_ratio = nu;
    EXPECT_TRUE(ros::service::call("liver_sim/set_capsule", srv));
    return srv.response;
  }

  static std::unique_ptr<ros::NodeHandle> nh_;
  static std::unique_ptr<tf2_ros::StaticTransformBroadcaster> tf_broadcaster_;
  static ros::Subscriber status_sub_, wrench_sub_, mesh_sub_;
  static ros::Publisher pose_pub_, cloud_pub_;
  static liver_sim::SimulationStatus status_;
  static geometry_msgs::WrenchStamped wrench_;
  static visualization_msgs::Marker mesh_;
  static unsigned status_count_, mesh_count_;
};

std::unique_ptr<ros::NodeHandle> Node::nh_;
std::unique_ptr<tf2_ros::StaticTransformBroadcaster> Node::tf_broadcaster_;
ros::Subscriber Node::status_sub_, Node::wrench_sub_, Node::mesh_sub_;
ros::Publisher Node::pose_pub_, Node::cloud_pub_;
liver_sim::SimulationStatus Node::status_;
geometry_msgs::WrenchStamped Node::wrench_;
visualization_msgs::Marker Node::mesh_;
unsigned Node::status_count_ = 0, Node::mesh_count_ = 0;

// A cloud of n points in frame liver, point i at point(i) (m).
template <typename Point>
sensor_msgs::PointCloud2 xyz_cloud(int n, const Point& point) {
  sensor_msgs::PointCloud2 cloud;
  cloud.header.frame_id = "liver";
  sensor_msgs::PointCloud2Modifier mod(cloud);
  mod.setPointCloud2FieldsByString(1, "xyz");
  mod.resize(n);
  sensor_msgs::PointCloud2Iterator<float> x(cloud, "x");
  for (int i = 0; i < n; ++i, ++x) {
    const Eigen::Vector3f p = point(i);
    x[0] = p.x();
    x[1] = p.y();
    x[2] = p.z();
  }
  return cloud;
}

// The mesh is sent when the shape changes (the rate at which meshes reflect poses is measured by
// scripts/measure_contact_node.sh, not asserted here).
TEST_F(Node, PublishesTheDeformedMeshWhenItChanges) {
  settled();
  wait_for([] { return false; }, 0.5);
  // Idle, the shape does not change: no mesh is re-sent (the status keeps flowing).
  const unsigned before = mesh_count_, statuses = status_count_;
  wait_for([] { return false; }, 1.0);
  EXPECT_EQ(mesh_count_, before) << "an unchanged mesh was re-sent";
  EXPECT_GT(status_count_, statuses + 2) << "the status stopped";
  EXPECT_EQ(mesh_.type, visualization_msgs::Marker::TRIANGLE_LIST);
  EXPECT_EQ(mesh_.header.frame_id, "liver");
  EXPECT_EQ(mesh_.points.size(), 3u * 768u);  // the cube's boundary triangles
  EXPECT_EQ(mesh_.colors.size(), mesh_.points.size());
  // Latched: a subscriber that comes late has the last one at once.
  visualization_msgs::Marker late;
  ros::Subscriber s = nh_->subscribe<visualization_msgs::Marker>(
      "liver_sim/mesh", 1, boost::function<void(const visualization_msgs::Marker::ConstPtr&)>(
                               [&late](const visualization_msgs::Marker::ConstPtr& m) { late = *m; }));
  EXPECT_TRUE(wait_for([&] { return !late.points.empty(); }, 10.0));
  EXPECT_EQ(late.points.size(), mesh_.points.size());
  const liver_sim::SimulationStatus st = settled();
  EXPECT_EQ(st.state, "idle");
  EXPECT_NEAR(st.max_displacement, 1.375e-3, 0.01e-3) << "the aspiration test at equilibrium";
}

// The model frame in the OR's tf tree (~parent_frame or, as here, a static_transform_publisher
// of the launch): tf resolves it.
TEST_F(Node, ModelFrameIsInTheTfTree) {
  tf2_ros::Buffer buffer;
  tf2_ros::TransformListener listener(buffer);
  EXPECT_TRUE(buffer.canTransform("or_world", "liver", ros::Time(0), ros::Duration(10.0)));
  const geometry_msgs::TransformStamped t = buffer.lookupTransform("or_world", "liver", ros::Time(0));
  EXPECT_DOUBLE_EQ(t.transform.translation.z, 0.9) << "the launch's ~parent_transform";
}

// Without its capsule the tissue lifts more under the same suction; invalid values are refused
// and change nothing.
TEST_F(Node, SetCapsuleChangesDisplacementAndRefusesInvalidValues) {
  const double with_capsule = settled().max_displacement;
  ros::Time sent = ros::Time::now();
  EXPECT_TRUE(set_capsule(false, 8.22e6, 20e-6, 0.45).success);
  const double without = settled(sent).max_displacement;
  EXPECT_GT(without, 2.0 * with_capsule);

  const unsigned rejected = status_.rejected_inputs;
  sent = ros::Time::now();
  EXPECT_FALSE(set_capsule(true, -1.0, 20e-6, 0.45).success);
  EXPECT_FALSE(set_capsule(true, 8e6, -1e-6, 0.45).success);
  EXPECT_FALSE(set_capsule(true, 8e6, 20e-6, 0.5).success);
  const liver_sim::SetCapsule::Response nan = set_capsule(true, std::nan(""), 20e-6, 0.45);
  EXPECT_FALSE(nan.success);
  EXPECT_NE(nan.message.find("young_modulus"), std::string::npos) << nan.message;
  const liver_sim::SimulationStatus after = settled(sent);
  EXPECT_DOUBLE_EQ(after.max_displacement, without) << "a refused request changed the model";
  EXPECT_EQ(after.rejected_inputs, rejected + 4);

  // Zeros keep the current values: switching the capsule back on names nothing else, and the
  // response tells the values in force.
  sent = ros::Time::now();
  const liver_sim::SetCapsule::Response on = set_capsule(true, 0, 0, 0);
  EXPECT_TRUE(on.success) << on.message;
  EXPECT_TRUE(on.enabled);
  EXPECT_EQ(on.young_modulus, 8.22e6);
  EXPECT_EQ(on.thickness, 20e-6);
  EXPECT_EQ(on.poisson_ratio, 0.45);
  EXPECT_NEAR(settled(sent).max_displacement, with_capsule, 1e-9);
}

// A probe brought against a side face of the cube, halfway up, then pushed 4 mm into it: the
// surface under it follows it about 4 mm, more than the suction lifts the top, and the tissue
// pushes the probe back. The poses come in the camera frame and are transformed with tf2.
TEST_F(Node, ProbePushedIntoTissueRaisesDisplacementAndWrench) {
  const double before = settled().max_displacement;
  const double r = 0.003;  // ~instrument_radius
  publish_pose(-r - 0.001 - 0.1, 0.0075, 0.0075, "camera");
  settled();
  const ros::Time sent = ros::Time::now();
  publish_pose(-r + 0.004 - 0.1, 0.0075, 0.0075, "camera");
  const liver_sim::SimulationStatus s = settled(sent);
  EXPECT_GT(s.active_contacts, 0);
  EXPECT_GT(s.max_displacement, before);
  EXPECT_GT(s.max_displacement, 3.5e-3) << "the surface under the probe follows it about 4 mm in";
  wait_for([] { return false; }, 0.3);
  EXPECT_LT(wrench_.wrench.force.x, -1e-3) << "the tissue pushes the probe back out";
}

TEST_F(Node, ResetRestoresTheRestShapeAndReleasesInstruments) {
  std_srvs::Trigger reset;
  const ros::Time sent = ros::Time::now();
  ASSERT_TRUE(ros::service::call("liver_sim/reset", reset));
  EXPECT_TRUE(reset.response.success);
  const liver_sim::SimulationStatus s = settled(sent);
  EXPECT_EQ(s.active_contacts, 0);
  // From the rest shape the scene's suction acts again: the same equilibrium as at start.
  EXPECT_NEAR(s.max_displacement, 1.375e-3, 0.01e-3);
  wait_for([] { return false; }, 0.3);
  EXPECT_EQ(wrench_.wrench.force.z, 0.0);
}

TEST_F(Node, MalformedInputIsRefusedAndCountedWhileTheNodeRuns) {
  const liver_sim::SimulationStatus before = settled();
  // One at a time: the node keeps only the latest message of a topic, by design.
  auto refused = [&](unsigned n) {
    return wait_for([&] { return status_.rejected_inputs >= before.rejected_inputs + n; }, 10.0);
  };
  publish_pose(std::nan(""), 0.0, 0.01);
  ASSERT_TRUE(refused(1)) << "NaN pose: " << status_.text;
  publish_pose(0.0075, 0.0075, 0.02, "no_such_frame");
  ASSERT_TRUE(refused(2)) << "unknown frame: " << status_.text;
  EXPECT_NE(status_.text.find("no_such_frame"), std::string::npos) << status_.text;
  sensor_msgs::PointCloud2 empty;
  empty.header.frame_id = "liver";
  sensor_msgs::PointCloud2Modifier(empty).setPointCloud2FieldsByString(1, "xyz");
  cloud_pub_.publish(empty);
  ASSERT_TRUE(refused(3)) << "empty cloud: " << status_.text;
  sensor_msgs::PointCloud2 truncated = empty;  // says 1000 points, carries none
  sensor_msgs::PointCloud2Modifier(truncated).resize(1000);
  truncated.data.clear();
  cloud_pub_.publish(truncated);
  ASSERT_TRUE(refused(4)) << "truncated cloud: " << status_.text;
  // Fields whose offsets wrap a 32-bit sum past point_step (PCL would read 4 GB away), and x
  // given for all three: refused, and the node lives on.
  sensor_msgs::PointCloud2 wrapped = xyz_cloud(100, [](int i) { return Eigen::Vector3f::Constant(0.001f * i); });
  for (size_t k = 0; k < 3; ++k) wrapped.fields[k].offset = 0xFFFFFFFCu + k;
  cloud_pub_.publish(wrapped);
  ASSERT_TRUE(refused(5)) << "wrapped offsets: " << status_.text;
  EXPECT_NE(status_.text.find("within point_step"), std::string::npos) << status_.text;
  sensor_msgs::PointCloud2 only_x = xyz_cloud(100, [](int i) { return Eigen::Vector3f::Constant(0.001f * i); });
  for (auto& f : only_x.fields) f.name = "x";
  cloud_pub_.publish(only_x);
  ASSERT_TRUE(refused(6)) << "x three times: " << status_.text;
  EXPECT_NE(status_.text.find("twice"), std::string::npos) << status_.text;
  EXPECT_NEAR(status_.max_displacement, before.max_displacement, 1e-12) << "refused input changed the model";
  EXPECT_EQ(status_.clouds_registered, before.clouds_registered);
  // Ten points on a line are too few to act (registration.min_points): refused.
  cloud_pub_.publish(xyz_cloud(10, [](int i) { return Eigen::Vector3f::Constant(0.001f * i); }));
  ASSERT_TRUE(refused(7)) << "ten points: " << status_.text;
  EXPECT_NE(status_.text.find("min_points"), std::string::npos) << status_.text;
  EXPECT_EQ(status_.clouds_registered, before.clouds_registered);
  // A cloud of the cube's top face (a sixth of its surface, 100 points 1.5 mm apart) is
  // registered and not counted as refused.
  cloud_pub_.publish(xyz_cloud(100, [](int i) {
    return Eigen::Vector3f(0.00075f + 0.0015f * (i % 10), 0.00075f + 0.0015f * (i / 10), 0.0151f);
  }));
  ASSERT_TRUE(wait_for([&] { return status_.clouds_registered == before.clouds_registered + 1; }, 10.0)) << status_.text;
  const unsigned count = status_count_;
  ASSERT_TRUE(wait_for([&] { return status_count_ > count + 5; }, 10.0)) << "status stopped flowing";
  EXPECT_EQ(status_.rejected_inputs, before.rejected_inputs + 7);
}

}  // namespace

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "liver_sim_node_test");
  return RUN_ALL_TESTS();
}
