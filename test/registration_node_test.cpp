// Registration in the node (rostest test/registration_node.test): point clouds of a lifted
// phantom, rendered here by the core and sent in a camera frame known only through tf2 (and
// known 3 mm and 1 degree wrong, which ~align_rigidly corrects on a first cloud of the
// unlifted liver), bring the node's tracked targets to where the lift put them, the hidden
// loads carrying the lift out of the camera's view; a 1M-point cloud
// is downsampled and registered; empty, NaN-filled, unknown-frame and too small clouds are
// refused, counted, and change nothing; the targets' covariances and ellipsoids follow; an
// analysis whose estimates change the model makes an idle node step.
#include <cctype>
#include <diagnostic_msgs/DiagnosticArray.h>
#include <geometry_msgs/PoseArray.h>
#include <gtest/gtest.h>
#include <pcl_conversions/pcl_conversions.h>
#include <ros/ros.h>
#include <sensor_msgs/PointCloud2.h>
#include <std_srvs/Trigger.h>
#include <tf2_ros/static_transform_broadcaster.h>
#include <visualization_msgs/MarkerArray.h>

#include <Eigen/Eigenvalues>
#include <cmath>

#include "liver_sim/SimulationStatus.h"
#include "liver_sim/TargetCovariances.h"
#include "liver_sim/registration/registration.h"
#include "scenarios.h"
#include "wait_for.h"

namespace {

using liver_sim_test::wait_for;

// The label rviz shows for target i, empty for none: a probe's name, but a probe "<stem>_centre"
// labels its group "<stem>_*" once, as "<stem>"; a bifurcation's vessel initial and number
// ("portal bifurcation 3": "P3").
std::string label(const std::vector<liver_sim::TrackedTarget>& targets, size_t i) {
  const liver_sim::TrackedTarget& t = targets[i];
  if (t.kind != liver_sim::TrackedTarget::Kind::Bifurcation) {
    const std::string stem = t.name.substr(0, t.name.rfind('_'));
    for (const liver_sim::TrackedTarget& c : targets)
      if (c.kind == t.kind && c.name == stem + "_centre") return t.name == c.name ? stem : "";
    return t.name;
  }
  const size_t digits = t.name.find_last_not_of("0123456789") + 1;
  return std::string(1, static_cast<char>(std::toupper(static_cast<unsigned char>(t.name[0])))) + t.name.substr(digits);
}

liver_sim::SimulationStatus status;
geometry_msgs::PoseArray target_poses;
visualization_msgs::MarkerArray target_markers, ellipsoids;
liver_sim::TargetCovariances covariances;
int status_count = 0, pose_count = 0, marker_count = 0, covariance_count = 0, ellipsoid_count = 0;
ros::WallTime last_analysis;  // when covariances of a new analysis came
int analyses = 0;  // analyses whose covariances came
double hidden_loads = -1;  // N, the sum /diagnostics reports
double analysis_time = -1;  // s, the processor time of the last analysis, as /diagnostics reports it
long steps = -1, factorizations = -1, past_cap = -1;  // /diagnostics: steps, the factorisations in them, the steps iterated past their cap

// The camera in the model frame: at the synthetic view's eye, turned 90 degrees about x, so
// that camera and model coordinates differ by a rotation and a translation.
Eigen::Isometry3d camera_in_liver(const liver_sim::CameraView& view) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = view.eye;
  T.linear() = Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitX()).toRotationMatrix();
  return T;
}

sensor_msgs::PointCloud2 to_message(const pcl::PointCloud<pcl::PointXYZ>& in_liver, const Eigen::Isometry3d& camera,
                                    const std::string& frame) {
  pcl::PointCloud<pcl::PointXYZ> in_camera;
  const Eigen::Isometry3d to_camera = camera.inverse();
  for (const pcl::PointXYZ& p : in_liver) {
    const Eigen::Vector3d q = to_camera * Eigen::Vector3d(p.x, p.y, p.z);
    in_camera.push_back(pcl::PointXYZ(q.x(), q.y(), q.z()));
  }
  sensor_msgs::PointCloud2 msg;
  pcl::toROSMsg(in_camera, msg);
  msg.header.frame_id = frame;
  msg.header.stamp = ros::Time::now();
  return msg;
}

TEST(RegistrationNode, TracksALiftSeenThroughACameraFrame) {
  ros::NodeHandle nh;
  using StatusPtr = liver_sim::SimulationStatus::ConstPtr;
  auto s1 = nh.subscribe<liver_sim::SimulationStatus>(
      "liver_sim/status", 10, boost::function<void(const StatusPtr&)>([](const StatusPtr& m) { status = *m, ++status_count; }));
  auto s2 = nh.subscribe<geometry_msgs::PoseArray>(
      "liver_sim/target_poses", 2,
      boost::function<void(const geometry_msgs::PoseArray::ConstPtr&)>([](const auto& m) { target_poses = *m, ++pose_count; }));
  auto s3 = nh.subscribe<visualization_msgs::MarkerArray>(
      "liver_sim/targets", 2,
      boost::function<void(const visualization_msgs::MarkerArray::ConstPtr&)>([](const auto& m) { target_markers = *m, ++marker_count; }));
  auto s4 = nh.subscribe<liver_sim::TargetCovariances>(
      "liver_sim/target_covariances", 2,
      boost::function<void(const liver_sim::TargetCovariances::ConstPtr&)>([](const auto& m) {
        if (covariance_count == 0 || m->analysis_stamp != covariances.analysis_stamp) {
          last_analysis = ros::WallTime::now();
          ++analyses;
        }
        covariances = *m, ++covariance_count;
      }));
  auto s5 = nh.subscribe<visualization_msgs::MarkerArray>(
      "liver_sim/target_ellipsoids", 2,
      boost::function<void(const visualization_msgs::MarkerArray::ConstPtr&)>([](const auto& m) { ellipsoids = *m, ++ellipsoid_count; }));
  auto s6 = nh.subscribe<diagnostic_msgs::DiagnosticArray>(
      "diagnostics", 10, boost::function<void(const diagnostic_msgs::DiagnosticArray::ConstPtr&)>([](const auto& m) {
        for (const diagnostic_msgs::DiagnosticStatus& d : m->status)
          for (const diagnostic_msgs::KeyValue& kv : d.values)
            if (kv.key == "hidden loads, sum of magnitudes (N)") hidden_loads = std::stod(kv.value);
            else if (kv.key == "last analysis processor time (s)") analysis_time = std::stod(kv.value);
            else if (kv.key == "steps") steps = std::stol(kv.value);
            else if (kv.key == "factorisations in the steps") factorizations = std::stol(kv.value);
            else if (kv.key == "steps iterated past their cap") past_cap = std::stol(kv.value);
      }));
  ros::Publisher cloud_pub = nh.advertise<sensor_msgs::PointCloud2>("points", 1);

  // Ground truth: the node's scene solved here, then lifted by 5 N under the right lobe.
  liver_sim::Scene scene = liver_sim::load_scene(std::string(LIVER_SIM_SOURCE_DIR) + "/config/scenes/liver_phantom.yaml");
  const liver_sim::TetMesh mesh = liver_sim::load_scene_mesh(scene);
  liver_sim::LiverModel rest(mesh, scene);
  ASSERT_TRUE(rest.step().converged());
  scene.loads.push_back(liver_sim::underside_lift(mesh, 5.0));
  liver_sim::LiverModel truth(mesh, scene);
  ASSERT_TRUE(truth.step().converged());
  const std::vector<liver_sim::TrackedTarget> before = liver_sim::tracked_targets(rest),
                                              expected = liver_sim::tracked_targets(truth);

  liver_sim::CameraView view = liver_sim::front_view(rest.positions());
  const Eigen::Isometry3d camera = camera_in_liver(view);
  // What tf says about the camera: off by 3 mm and 1 degree (a calibration error).
  const Eigen::Isometry3d calibrated =
      camera * Eigen::Translation3d(0.002, -0.002, 0.001) * Eigen::AngleAxisd(M_PI / 180, Eigen::Vector3d(1, 1, 0).normalized());
  tf2_ros::StaticTransformBroadcaster broadcaster;
  geometry_msgs::TransformStamped tf;
  tf.header.stamp = ros::Time::now();
  tf.header.frame_id = "liver";
  tf.child_frame_id = "camera";
  tf.transform.translation.x = calibrated.translation().x();
  tf.transform.translation.y = calibrated.translation().y();
  tf.transform.translation.z = calibrated.translation().z();
  const Eigen::Quaterniond q(calibrated.linear());
  tf.transform.rotation.x = q.x();
  tf.transform.rotation.y = q.y();
  tf.transform.rotation.z = q.z();
  tf.transform.rotation.w = q.w();
  broadcaster.sendTransform(tf);

  ASSERT_TRUE(wait_for([] { return status_count > 0 && status.state == "idle" && pose_count > 0 && marker_count > 0; }, 60.0));
  ASSERT_EQ(target_poses.poses.size(), before.size());
  size_t spheres = 0, names = 0, labelled = 0;  // beside them: the names and the colour legend
  for (size_t i = 0; i < before.size(); ++i) labelled += !label(before, i).empty();
  for (const visualization_msgs::Marker& m : target_markers.markers) {
    spheres += m.type == visualization_msgs::Marker::SPHERE;
    if (m.ns == "target_names" && m.id < static_cast<int>(before.size()))
      names += !m.text.empty() && m.text == label(before, m.id);
  }
  EXPECT_EQ(spheres, before.size());
  EXPECT_GT(labelled, 0u);
  EXPECT_EQ(names, labelled) << "each labelled target's label names it in the core";
  for (size_t i = 0; i < before.size(); ++i) {
    const auto& p = target_poses.poses[i].position;
    EXPECT_LT((Eigen::Vector3d(p.x, p.y, p.z) - before[i].position).norm(), 1e-6) << before[i].name;
  }
  ASSERT_TRUE(wait_for([&] { return cloud_pub.getNumSubscribers() > 0; }, 10.0));

  // Refused: empty, all NaN, a frame tf does not know. Nothing registered, nothing moved.
  const uint32_t rejected = status.rejected_inputs;
  const double displacement = status.max_displacement;
  pcl::PointCloud<pcl::PointXYZ> nan_cloud;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (int i = 0; i < 1000; ++i) nan_cloud.push_back(pcl::PointXYZ(nan, nan, nan));
  view.noise = 1e-3;
  view.seed = 1;
  const pcl::PointCloud<pcl::PointXYZ> seen = liver_sim::render_surface_cloud(truth.positions(), truth.boundary(), view).cloud;
  sensor_msgs::PointCloud2 empty = to_message(pcl::PointCloud<pcl::PointXYZ>(), camera, "camera");
  cloud_pub.publish(empty);
  ASSERT_TRUE(wait_for([&] { return status.rejected_inputs == rejected + 1; }, 10.0)) << status.text;
  cloud_pub.publish(to_message(nan_cloud, camera, "camera"));
  ASSERT_TRUE(wait_for([&] { return status.rejected_inputs == rejected + 2; }, 10.0)) << status.text;
  cloud_pub.publish(to_message(seen, camera, "nowhere"));
  ASSERT_TRUE(wait_for([&] { return status.rejected_inputs == rejected + 3; }, 10.0)) << status.text;
  EXPECT_NE(status.text.find("nowhere"), std::string::npos) << status.text;
  // Too few points to act (registration.min_points): refused, not a spike.
  pcl::PointCloud<pcl::PointXYZ> few;
  for (int i = 0; i < scene.registration.min_points / 2; ++i) few.push_back(seen[i * seen.size() / scene.registration.min_points]);
  cloud_pub.publish(to_message(few, camera, "camera"));
  ASSERT_TRUE(wait_for([&] { return status.rejected_inputs == rejected + 4; }, 10.0)) << status.text;
  EXPECT_NE(status.text.find("min_points"), std::string::npos) << status.text;
  EXPECT_EQ(status.clouds_registered, 0u);
  EXPECT_EQ(status.max_displacement, displacement);
  EXPECT_EQ(covariance_count, 0);  // no registration, no uncertainty analysis

  // The rigid alignment, asked for by service, on a cloud of the liver before the lift.
  ros::ServiceClient align = nh.serviceClient<std_srvs::Trigger>("liver_sim/align_rigidly");
  ASSERT_TRUE(align.waitForExistence(ros::Duration(10.0)));
  EXPECT_FALSE(status.rigid_alignment_active);
  std_srvs::Trigger call;
  ASSERT_TRUE(align.call(call) && call.response.success);
  cloud_pub.publish(to_message(liver_sim::render_surface_cloud(rest.positions(), rest.boundary(), view).cloud, camera, "camera"));
  ASSERT_TRUE(wait_for([&] { return status.clouds_registered == 1u; }, 30.0)) << status.text;
  EXPECT_LT(status.registration_rms, 1.0e-3);
  // The status reports the alignment found: the calibration error undone, camera * calibrated^-1.
  EXPECT_TRUE(status.rigid_alignment_active);
  const Eigen::Vector3d undone = (camera * calibrated.inverse()).translation();
  const auto& found = status.rigid_alignment.translation;
  EXPECT_LT((Eigen::Vector3d(found.x, found.y, found.z) - undone).norm(), 1.0e-3)
      << "found " << found.x << " " << found.y << " " << found.z << ", expected " << undone.transpose();

  // Registered: a 1M-point cloud first (downsampled in the node), then 9 ordinary ones.
  liver_sim::CameraView dense = view;
  dense.spacing = 0.15e-3;
  const pcl::PointCloud<pcl::PointXYZ> huge = liver_sim::render_surface_cloud(truth.positions(), truth.boundary(), dense).cloud;
  ASSERT_GE(huge.size(), 1000000u);
  for (int k = 0; k < 10; ++k) {
    view.seed = 10 + k;
    cloud_pub.publish(to_message(
        k == 0 ? huge : liver_sim::render_surface_cloud(truth.positions(), truth.boundary(), view).cloud, camera, "camera"));
    ASSERT_TRUE(wait_for([&] { return status.clouds_registered == static_cast<uint64_t>(k + 2); }, 30.0))
        << "cloud " << k << " not registered: " << status.text;
    EXPECT_GT(status.correspondences, 500);
    EXPECT_LE(status.correspondences, scene.registration.max_points);
  }
  // The last cloud's analysis, its estimates solved: idle, and no analysis for 3 s (one is due
  // at most once per ~uncertainty_period, 1 s, after a registered cloud).
  ASSERT_TRUE(wait_for([&] {
    return status.state == "idle" && covariance_count > 0 && ros::WallTime::now() - last_analysis > ros::WallDuration(3.0);
  }, 60.0)) << status.state << " " << status.text;
  const ros::Time settled = ros::Time::now();
  ASSERT_TRUE(wait_for([&] { return status.state == "idle" && status.header.stamp > settled && pose_count > 0; }, 60.0))
      << status.state << " " << status.text;
  wait_for([] { return false; }, 0.5);  // the targets of the last step's shape (sent when it changes)
  EXPECT_EQ(status.rejected_inputs, rejected + 4);
  EXPECT_LT(status.registration_rms, 1.5e-3);  // the clouds' 1 mm noise, with the voxel grid's averaging

  double unregistered = 0, mean = 0, worst = 0, tumour = 0;
  int tumour_points = 0;
  for (size_t i = 0; i < expected.size(); ++i) {
    const auto& p = target_poses.poses[i].position;
    const double d = (Eigen::Vector3d(p.x, p.y, p.z) - expected[i].position).norm();
    unregistered += (before[i].position - expected[i].position).norm() / expected.size();
    mean += d / expected.size();
    worst = std::max(worst, d);
    if (expected[i].kind == liver_sim::TrackedTarget::Kind::Probe) {
      tumour = std::max(tumour, d);
      ++tumour_points;
    }
  }
  ASSERT_GT(tumour_points, 0);
  // The hidden loads carry the lift the camera does not see: their sum near the 5 N applied
  // (4.1-4.8 N over runs), the targets within a fraction of the motion (mean 0.35-0.37 mm of
  // 8.4 mm, the tumour 0.46-0.47 mm, the worst 0.57-0.58 mm). Mutations seen failing: the
  // springs alone (no loads; mean 0.82 mm, the tumour 1.09 mm, the worst 2.78 mm); the loads'
  // fit read at the state the frames reached instead of its equilibrium (7.9 N; 1.30, 1.63,
  // 3.58 mm).
  EXPECT_NEAR(hidden_loads, 5.0, 2.0);
  EXPECT_LT(mean, 0.08 * unregistered) << "unregistered " << unregistered;
  EXPECT_LT(tumour, 1e-3);
  EXPECT_LT(worst, 2e-3);
  // What the node reports of its work: the first step factorised, and no frame more than a
  // handful of times (a cloud's frame: three updates, each factorised at most twice); the
  // analysis, a factorisation of the phantom (~1e9 floating-point operations), cannot have
  // taken under a millisecond.
  EXPECT_GE(factorizations, 1);
  EXPECT_LE(factorizations, 8 * steps);
  EXPECT_GE(past_cap, 0) << "no count of the steps iterated past their cap on /diagnostics";
  EXPECT_LE(past_cap, steps);
  EXPECT_GT(analysis_time, 1e-3);

  // The targets' uncertainty: every target, in the order of ~target_poses, with a symmetric
  // positive semi-definite position block (m^2) and its 95% ellipsoid.
  ASSERT_TRUE(wait_for([&] { return covariance_count > 0 && ellipsoid_count > 0; }, 10.0));
  ASSERT_EQ(covariances.names.size(), expected.size());
  ASSERT_EQ(covariances.poses.size(), expected.size());
  ASSERT_EQ(ellipsoids.markers.size(), expected.size());
  EXPECT_GT(status.target_radius_95, 0.0);
  for (size_t i = 0; i < expected.size(); ++i) {
    EXPECT_EQ(covariances.names[i], expected[i].name);
    Eigen::Matrix3d c;
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) c(a, b) = covariances.poses[i].covariance[6 * a + b];
    EXPECT_LT((c - c.transpose()).norm(), 1e-12 * c.norm()) << expected[i].name;
    EXPECT_GE(Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(c).eigenvalues().minCoeff(), -1e-12 * c.norm()) << expected[i].name;
    EXPECT_GT(c.trace(), 0.0) << expected[i].name;
  }

  // The lift let go, seen in two clouds of the liver at rest sent one after the other: the
  // second's analysis waits for ~uncertainty_period after the first's, by when the node is
  // usually idle. An analysis's estimates (the hidden loads' fit, on its way from the lift's
  // ~5 N back towards none) change the model with no input to come, and the node must step on
  // them. Dropping that step (stepping only on clouds, poses and unconverged steps) leaves the
  // node idle on loads it never solved: killed (tried). Up to three pairs, until one is seen
  // idle with an analysis still to come (an idle node steps on nothing else).
  bool landed_idle = false;
  for (int pair = 0; pair < 3 && !landed_idle; ++pair) {
    ASSERT_TRUE(wait_for([&] { return ros::WallTime::now() - last_analysis > ros::WallDuration(1.5); }, 30.0));
    const int analysed = analyses;
    for (int k = 0; k < 2; ++k) {
      const uint64_t registered = status.clouds_registered;
      view.seed = 30 + 2 * pair + k;
      cloud_pub.publish(to_message(liver_sim::render_surface_cloud(rest.positions(), rest.boundary(), view).cloud, camera, "camera"));
      ASSERT_TRUE(wait_for([&] { return status.clouds_registered == registered + 1; }, 30.0)) << status.text;
    }
    ASSERT_TRUE(wait_for([&] { return status.state == "idle" || analyses == analysed + 2; }, 30.0)) << status.text;
    const uint64_t idle_step = status.step;
    // The covariances come on a topic of their own: a late one may be of an analysis adopted
    // before the idle status. Still idle, on the same step and with an analysis to come after
    // a short wait: none was.
    wait_for([] { return false; }, 0.2);
    if (analyses == analysed + 2 || status.step != idle_step) continue;
    landed_idle = true;
    ASSERT_TRUE(wait_for([&] { return analyses == analysed + 2; }, 10.0))
        << "one analysis per cloud expected; the second cloud's did not come";
    EXPECT_TRUE(wait_for([&] { return status.step > idle_step; }, 2.0)) << "no step on the estimates of an analysis";
  }
  EXPECT_TRUE(landed_idle) << "in three pairs of clouds the node was never seen idle with an analysis to come";
}

}  // namespace

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "registration_node_test");
  return RUN_ALL_TESTS();
}
