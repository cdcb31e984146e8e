// rostest test/reconfigure.test: each dynamic_reconfigure parameter of the node, changed live,
// and its effect on what the node publishes. Rates are checked from above only (a slow machine
// lowers them; it cannot raise them).
#include <dynamic_reconfigure/Reconfigure.h>
#include <geometry_msgs/PoseStamped.h>
#include <geometry_msgs/WrenchStamped.h>
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <sensor_msgs/PointCloud2.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <visualization_msgs/Marker.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>

#include "liver_sim/SimulationStatus.h"
#include "wait_for.h"

namespace {

using liver_sim_test::wait_for;
constexpr double kL = 0.015;  // the probe cube's edge (m)

class Reconfigure : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    nh_ = std::make_unique<ros::NodeHandle>();
    status_sub_ = nh_->subscribe("liver_sim/status", 100, &Reconfigure::on_status);
    mesh_sub_ = nh_->subscribe("liver_sim/mesh", 10, &Reconfigure::on_mesh);
    wrench_sub_ = nh_->subscribe("liver_sim/wrench", 10, &Reconfigure::on_wrench);
    pose_pub_ = nh_->advertise<geometry_msgs::PoseStamped>("instruments/tool/pose", 1);
    cloud_pub_ = nh_->advertise<sensor_msgs::PointCloud2>("points", 1);
    ASSERT_TRUE(wait_for([] { return meshes_ > 0 && pose_pub_.getNumSubscribers() > 0; }, 60.0));
    ASSERT_TRUE(ros::service::waitForService("liver_sim/set_parameters", 30000));
  }
  static void on_status(const liver_sim::SimulationStatus::ConstPtr& m) {
    status_ = *m;
    statuses_.push_back(*m);
  }
  static void on_mesh(const visualization_msgs::Marker::ConstPtr& m) {
    mesh_ = *m;
    ++meshes_;
  }
  static void on_wrench(const geometry_msgs::WrenchStamped::ConstPtr& m) { wrench_ = *m; }
  static void TearDownTestSuite() {
    status_sub_ = mesh_sub_ = wrench_sub_ = ros::Subscriber();
    pose_pub_ = cloud_pub_ = ros::Publisher();
    nh_.reset();
  }

  // Sets parameters through the node's dynamic_reconfigure service; returns the config in force.
  static dynamic_reconfigure::Config set(const std::vector<std::pair<std::string, double>>& doubles,
                                         const std::vector<std::pair<std::string, int>>& ints = {},
                                         const std::vector<std::pair<std::string, std::string>>& strs = {},
                                         const std::vector<std::pair<std::string, bool>>& bools = {}) {
    dynamic_reconfigure::Reconfigure srv;
    for (const auto& [n, v] : doubles) srv.request.config.doubles.push_back(dp(n, v));
    for (const auto& [n, v] : ints) {
      dynamic_reconfigure::IntParameter p;
      p.name = n;
      p.value = v;
      srv.request.config.ints.push_back(p);
    }
    for (const auto& [n, v] : strs) {
      dynamic_reconfigure::StrParameter p;
      p.name = n;
      p.value = v;
      srv.request.config.strs.push_back(p);
    }
    for (const auto& [n, v] : bools) {
      dynamic_reconfigure::BoolParameter p;
      p.name = n;
      p.value = v;
      srv.request.config.bools.push_back(p);
    }
    EXPECT_TRUE(ros::service::call("liver_sim/set_parameters", srv));
    wait_for([] { return false; }, 0.2);  // applied at the next frame
    return srv.response.config;
  }
  static dynamic_reconfigure::DoubleParameter dp(const std::string& n, double v) {
    dynamic_reconfigure::DoubleParameter p;
    p.name = n;
    p.value = v;
    return p;
  }

  // Publishes the tool's pose (the 3 mm rod's tip, m) every 50 ms until the model idles, or for
  // `seconds` when given.
  static liver_sim::SimulationStatus press(double x, double y, double depth, double seconds = 0) {
    geometry_msgs::PoseStamped p;
    p.header.frame_id = "liver";
    p.pose.position.x = x;
    p.pose.position.y = y;
    p.pose.position.z = kL + 0.003 - depth;
    p.pose.orientation.w = 1;
    statuses_.clear();
    const ros::Time sent = ros::Time::now();
    const ros::WallTimer tracker = nh_->createWallTimer(ros::WallDuration(0.05), [&](const ros::WallTimerEvent&) {
      p.header.stamp = ros::Time::now();
      pose_pub_.publish(p);
    });
    if (seconds > 0) {
      wait_for([] { return false; }, seconds);
      return status_;
    }
    EXPECT_TRUE(wait_for([&] { return status_.header.stamp > sent + ros::Duration(0.3) && status_.state == "idle"; }, 120.0))
        << status_.state << ": " << status_.text << " residual " << status_.residual << " it " << status_.iterations;
    return status_;
  }
  // Steps the model took for the statuses since the last press.
  static int steps_taken() {
    int n = 0;
    for (const auto& s : statuses_) n = std::max<int>(n, s.step);
    return n - static_cast<int>(statuses_.front().step);
  }

  static std::unique_ptr<ros::NodeHandle> nh_;
  static ros::Subscriber status_sub_, mesh_sub_, wrench_sub_;
  static ros::Publisher pose_pub_, cloud_pub_;
  static liver_sim::SimulationStatus status_;
  static std::vector<liver_sim::SimulationStatus> statuses_;
  static visualization_msgs::Marker mesh_;
  static geometry_msgs::WrenchStamped wrench_;
  static unsigned meshes_;
};

std::unique_ptr<ros::NodeHandle> Reconfigure::nh_;
ros::Subscriber Reconfigure::status_sub_, Reconfigure::mesh_sub_, Reconfigure::wrench_sub_;
ros::Publisher Reconfigure::pose_pub_, Reconfigure::cloud_pub_;
liver_sim::SimulationStatus Reconfigure::status_;
std::vector<liver_sim::SimulationStatus> Reconfigure::statuses_;
visualization_msgs::Marker Reconfigure::mesh_;
geometry_msgs::WrenchStamped Reconfigure::wrench_;
unsigned Reconfigure::meshes_ = 0;

// strategy, max_iterations, tolerance: full Newton allowed 50 iterations converges a press in
// fewer steps, and more iterations a step, than modified Newton allowed one; a looser tolerance
// takes fewer steps than a tight one and ends within it.
TEST_F(Reconfigure, SolverSettingsChangeHowTheModelConverges) {
  set({{"tolerance", 1e-10}}, {{"max_iterations", 1}}, {{"strategy", "modified_newton"}});
  press(0.0075, 0.0075, 0.001);
  const int capped = steps_taken();
  auto most_iterations = [] {
    int n = 0;
    for (const auto& s : statuses_) n = std::max(n, s.state == "idle" ? 0 : s.iterations);
    return n;
  };
  const int capped_iterations = most_iterations();
  set({}, {{"max_iterations", 50}}, {{"strategy", "full_newton"}});
  press(0.0075, 0.0075, 0.002);
  const int full = steps_taken();
  EXPECT_LT(full, capped) << "full Newton with 50 iterations a frame";
  EXPECT_GT(most_iterations(), capped_iterations) << "a step's iterations (its stages' together) follow the cap";
  set({{"tolerance", 1e-3}}, {{"max_iterations", 1}}, {{"strategy", "modified_newton"}});
  press(0.0075, 0.0075, 0.001);
  const int loose = steps_taken();
  EXPECT_LT(loose, capped) << "tolerance 1e-3 against 1e-10, the same press";
  EXPECT_LE(status_.residual, 1e-3);
  // Out of its bounds a value is clamped by the config: at least one iteration.
  const dynamic_reconfigure::Config c = set({}, {{"max_iterations", 0}});
  ASSERT_FALSE(c.ints.empty());
  for (const auto& p : c.ints) {
    if (p.name == "max_iterations") {
      EXPECT_EQ(p.value, 1);
    }
  }
  set({{"tolerance", 1e-8}}, {{"max_iterations", 2}});
}

// rate and publish_rate bound what the node does per second (checked from above).
TEST_F(Reconfigure, RatesBoundStepsAndMeshes) {
  set({{"rate", 5.0}, {"publish_rate", 1.0}}, {{"max_iterations", 1}}, {{"strategy", "modified_newton"}});
  wait_for([] { return false; }, 1.5);  // the last second's steps were at the former rate
  const unsigned before = meshes_;
  const ros::WallTime t0 = ros::WallTime::now();
  press(0.0075, 0.004, 0.002, 3.0);  // at 5 Hz and one iteration a step the press would take ~15 s to settle
  const double elapsed = (ros::WallTime::now() - t0).toSec();
  for (const auto& s : statuses_) EXPECT_LE(s.rate, 6.0) << "steps in the last second at 5 Hz";
  EXPECT_LE(meshes_ - before, elapsed * 1.0 + 2) << elapsed << " s at 1 Hz";
  set({{"rate", 30.0}, {"publish_rate", 15.0}}, {{"max_iterations", 2}});
}

// surface_alpha and color_scale_max: the mesh's opacity and how red a displacement is drawn.
TEST_F(Reconfigure, DisplaySettingsChangeTheMesh) {
  set({{"pose_timeout", 0.0}});  // the tool stays when its poses stop
  press(0.0075, 0.0075, 0.002);
  auto red_vertices = [] {  // at the colour ramp's end (dark red, no green), shaded
    int n = 0;
    for (const auto& c : mesh_.colors) n += c.r > 0.2f && c.g < 0.01f;
    return n;
  };
  unsigned seen = meshes_;
  set({{"color_scale_max", 0.2}, {"surface_alpha", 0.5}});
  EXPECT_TRUE(wait_for([&] { return meshes_ > seen; }, 10.0)) << "a display change re-sends the mesh";
  EXPECT_EQ(red_vertices(), 0) << "2 mm of 200 mm is near the ramp's start";
  EXPECT_FLOAT_EQ(mesh_.colors.front().a, 0.5f);
  seen = meshes_;
  set({{"color_scale_max", 1e-4}, {"surface_alpha", 1.0}});
  EXPECT_TRUE(wait_for([&] { return meshes_ > seen; }, 10.0)) << "a display change re-sends the mesh";
  EXPECT_GT(red_vertices(), 10) << "displacements over 0.1 mm are red";
  EXPECT_FLOAT_EQ(mesh_.colors.front().a, 1.0f);
  set({{"color_scale_max", 0.005}, {"pose_timeout", 1.0}});
}

// friction: dragging the pressed tool sideways, the tissue resists along the drag with friction
// and far less without it.
TEST_F(Reconfigure, FrictionResistsADrag) {
  auto drag = [](double mu) {
    set({{"friction", mu}}, {{"max_iterations", 2}});
    press(0.0075, 0.0075, 0.0);  // lift off, then press and drag 1 mm along x
    press(0.0075, 0.0075, 0.0015);
    press(0.0085, 0.0075, 0.0015);
    wait_for([] { return false; }, 0.3);
    return std::abs(wrench_.wrench.force.x);
  };
  const double with = drag(0.5), without = drag(0.0);
  EXPECT_GT(with, 2 * without + 1e-4) << "friction 0.5: " << with << " N, none: " << without << " N";
}

// registration_stiffness: the same cloud 1 mm above the top face lifts it more when its springs
// are stiffer.
TEST_F(Reconfigure, RegistrationStiffnessScalesThePull) {
  press(0.0075, 0.0075, -0.01);  // the tool well away
  auto lift = [](double k) {
    set({{"registration_stiffness", k}});
    sensor_msgs::PointCloud2 cloud;
    cloud.header.frame_id = "liver";
    sensor_msgs::PointCloud2Modifier mod(cloud);
    mod.setPointCloud2FieldsByString(1, "xyz");
    mod.resize(400);
    sensor_msgs::PointCloud2Iterator<float> it(cloud, "x");
    for (int i = 0; i < 400; ++i, ++it) {
      it[0] = 0.0005f + 0.0007f * (i % 20);
      it[1] = 0.0005f + 0.0007f * (i / 20);
      it[2] = kL + 0.001f;
    }
    const uint64_t registered = status_.clouds_registered;
    for (int k = 0; k < 5; ++k) {  // a camera sends the same view a few times
      cloud.header.stamp = ros::Time::now();
      cloud_pub_.publish(cloud);
      wait_for([] { return false; }, 0.2);
    }
    EXPECT_GT(status_.clouds_registered, registered) << status_.text;
    const ros::Time sent = ros::Time::now();
    wait_for([&] { return status_.header.stamp > sent && status_.state == "idle"; }, 60.0);
    return status_.max_displacement;
  };
  const double soft = lift(1e2), stiff = lift(1e6);
  EXPECT_GT(stiff, 2 * soft) << "1e6 N/m: " << stiff << " m, 1e2 N/m: " << soft << " m";
}

// pose_timeout and hold_stale_instruments: when the poses stop, a held tool stays in contact;
// otherwise it is withdrawn after the timeout.
TEST_F(Reconfigure, StalePosesHoldOrWithdraw) {
  auto has_tool = [] {
    return std::find(status_.instrument_names.begin(), status_.instrument_names.end(), "tool") != status_.instrument_names.end();
  };
  set({{"pose_timeout", 0.5}}, {}, {}, {{"hold_stale_instruments", true}});
  press(0.0075, 0.0075, 0.001);  // the poses stop when it returns
  wait_for([] { return false; }, 2.0);
  EXPECT_TRUE(has_tool()) << "held";
  set({}, {}, {}, {{"hold_stale_instruments", false}});
  EXPECT_TRUE(wait_for([&] { return !has_tool(); }, 10.0)) << "the held tool withdrawn once holding is off";
}

// dynamic_reconfigure's clamp lets NaN through, and any string for the strategy: the node
// refuses them at the next frame (a NaN colour scale would index the colour ramp far out of
// bounds), counts the refusal, shows the values in force again and keeps publishing.
TEST_F(Reconfigure, NaNAndUnknownStrategiesAreRefused) {
  const dynamic_reconfigure::Config before = set({});
  const unsigned rejected = status_.rejected_inputs;
  auto told = [](const std::string& what) {  // by a status since the last clear (the next one only says it)
    return std::any_of(statuses_.begin(), statuses_.end(),
                       [&](const auto& s) { return s.text.find(what) != std::string::npos; });
  };
  statuses_.clear();
  set({{"color_scale_max", std::nan("")}});
  ASSERT_TRUE(wait_for([&] { return status_.rejected_inputs == rejected + 1; }, 10.0)) << status_.text;
  EXPECT_TRUE(told("color_scale_max"));
  statuses_.clear();
  set({}, {}, {{"strategy", "no_such_strategy"}});
  ASSERT_TRUE(wait_for([&] { return status_.rejected_inputs == rejected + 2; }, 10.0)) << status_.text;
  EXPECT_TRUE(told("unknown strategy"));
  const dynamic_reconfigure::Config shown = set({});
  EXPECT_EQ(shown.doubles, before.doubles);
  EXPECT_EQ(shown.strs, before.strs);
  const unsigned seen = meshes_;
  press(0.0075, 0.0075, 0.001);
  EXPECT_GT(meshes_, seen) << "the mesh is still published";
  EXPECT_EQ(status_.rejected_inputs, rejected + 2);
}

// A value past the config's bounds is clamped to them and said, naming the value asked: in the
// reply, in ~status (and the log). dynamic_reconfigure's own server clamps before anyone sees the
// request: friction 5 became 2 without a word.
TEST_F(Reconfigure, ValuesPastTheBoundsAreClampedAndSaid) {
  auto friction = [](const dynamic_reconfigure::Config& c) {
    for (const auto& d : c.doubles)
      if (d.name == "friction") return d.value;
    return std::nan("");
  };
  const double before = friction(set({}));
  statuses_.clear();
  const unsigned rejected = status_.rejected_inputs;
  EXPECT_EQ(friction(set({{"friction", 5.0}})), 2.0);
  EXPECT_TRUE(wait_for(
      [] {
        return std::any_of(statuses_.begin(), statuses_.end(),
                           [](const auto& s) { return s.text.find("friction 5 -> 2") != std::string::npos; });
      },
      10.0))
      << status_.text;
  EXPECT_EQ(status_.rejected_inputs, rejected) << "a clamp is not a refusal";
  EXPECT_EQ(friction(set({{"friction", before}})), before);
}

}  // namespace

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "reconfigure_test");
  return RUN_ALL_TESTS();
}
