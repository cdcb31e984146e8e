// rostest test/instruments.test: a grasper (closing, lifting, opening) and a probe at once, each
// driven by its own tf frame, against the same scene solved by the core in this process. The
// node's per-instrument wrench (instrument frame, at the tip) must equal the core's reaction
// turned into that frame: publishing the model-frame force instead fails the probe's check (its
// frame is tilted 30 degrees), as does a wrench taken from the other instrument.
#include <dynamic_reconfigure/Reconfigure.h>
#include <geometry_msgs/PoseStamped.h>
#include <geometry_msgs/WrenchStamped.h>
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <tf2_msgs/TFMessage.h>
#include <visualization_msgs/MarkerArray.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <map>
#include <mutex>
#include <thread>

#include "liver_sim/InstrumentCommand.h"
#include "liver_sim/SimulationStatus.h"
#include "liver_sim/simulation/liver_model.h"
#include "wait_for.h"

namespace {

using liver_sim::InstrumentOptions;
using liver_sim_test::wait_for;

constexpr double kL = 0.015;  // the probe cube's edge (m)

// The OR's tracking system: one tf frame per instrument, broadcast at 50 Hz from its own thread
// (whatever the test thread is doing).
class Tracker {
 public:
  Tracker() : tf_pub_(ros::NodeHandle().advertise<tf2_msgs::TFMessage>("/tf", 100)), thread_([this] {
    while (running_) {
      broadcast();
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
  }) {}
  ~Tracker() {
    running_ = false;
    thread_.join();
  }
  void set(const std::string& frame, const Eigen::Isometry3d& pose) {
    std::lock_guard<std::mutex> lock(mutex_);
    frames_[frame] = pose;
  }
  Eigen::Isometry3d get(const std::string& frame) {
    std::lock_guard<std::mutex> lock(mutex_);
    return frames_.count(frame) ? frames_[frame] : Eigen::Isometry3d::Identity();
  }
  // The node listens: its tf buffer has the frames from the next broadcast on. (On a loaded
  // machine a new publisher's connection takes longer than the node's wait for a declared frame.)
  bool heard() const { return tf_pub_.getNumSubscribers() > 0; }

 private:
  void broadcast() {
    std::lock_guard<std::mutex> lock(mutex_);
    tf2_msgs::TFMessage message;
    for (const auto& [name, pose] : frames_) {
      geometry_msgs::TransformStamped t;
      t.header.stamp = ros::Time::now();
      t.header.frame_id = "liver";
      t.child_frame_id = name;
      const Eigen::Quaterniond q(pose.linear());
      t.transform.translation.x = pose.translation().x();
      t.transform.translation.y = pose.translation().y();
      t.transform.translation.z = pose.translation().z();
      t.transform.rotation.x = q.x();
      t.transform.rotation.y = q.y();
      t.transform.rotation.z = q.z();
      t.transform.rotation.w = q.w();
      message.transforms.push_back(t);
    }
    if (!message.transforms.empty()) tf_pub_.publish(message);
  }
  ros::Publisher tf_pub_;
  std::mutex mutex_;
  std::map<std::string, Eigen::Isometry3d> frames_;
  std::atomic<bool> running_{true};
  std::thread thread_;
};

liver_sim::SimulationStatus status;
std::vector<std::string> texts;  // status texts since the last clear

void on_status_with_text(const liver_sim::SimulationStatus::ConstPtr& m) {
  status = *m;
  if (!m->text.empty()) texts.push_back(m->text);
}
std::map<std::string, geometry_msgs::WrenchStamped> wrenches;
geometry_msgs::WrenchStamped total;
visualization_msgs::MarkerArray markers;

// Waits for an idle status stamped well after `sent` (an input is applied within a frame).
liver_sim::SimulationStatus settled(const ros::Time& sent) {
  const ros::Time after = sent + ros::Duration(0.3);
  EXPECT_TRUE(wait_for([&] { return status.header.stamp > after && status.state == "idle"; }, 120.0))
      << "state " << status.state << ": " << status.text;
  wait_for([] { return false; }, 0.3);  // the wrenches of the settled state
  return status;
}

// The core's equilibrium for the same instruments (static scene: one step converges).
void solve(liver_sim::LiverModel& model) {
  for (int i = 0; i < 10; ++i)
    if (model.step().converged()) return;
  ADD_FAILURE() << "the core's reference did not converge";
}

// The node's wrench of `name` against the core's reaction of instrument k in the frame `pose`.
void expect_wrench(const std::string& name, const liver_sim::LiverModel& model, int k, const Eigen::Isometry3d& pose,
                   const std::string& stage) {
  ASSERT_TRUE(wrenches.count(name)) << "no wrench of " << name;
  const geometry_msgs::WrenchStamped& w = wrenches[name];
  EXPECT_EQ(w.header.frame_id, name + "_tf");
  const Eigen::Vector3d expected = pose.linear().transpose() * model.instrument_reaction(k).force;
  const Eigen::Vector3d got(w.wrench.force.x, w.wrench.force.y, w.wrench.force.z);
  EXPECT_LE((got - expected).norm(), 0.03 * expected.norm() + 1e-4)
      << stage << ", " << name << ": node " << got.transpose() << " N, core " << expected.transpose() << " N";
  // The torque about the tip, in the same frame (N m; a lever of the instrument's size).
  const Eigen::Vector3d torque = pose.linear().transpose() * model.instrument_reaction(k).torque;
  const Eigen::Vector3d got_torque(w.wrench.torque.x, w.wrench.torque.y, w.wrench.torque.z);
  EXPECT_LE((got_torque - torque).norm(), 0.03 * torque.norm() + 1e-4 * 0.003)
      << stage << ", " << name << ": node " << got_torque.transpose() << " N m, core " << torque.transpose() << " N m";
}

// The node's total (model frame, torque about its origin) against the core's instruments.
void expect_total(const liver_sim::LiverModel& model, const std::string& stage) {
  Eigen::Vector3d force = Eigen::Vector3d::Zero(), torque = Eigen::Vector3d::Zero();
  for (int k = 0; k < model.num_instruments(); ++k) {
    const liver_sim::InstrumentReaction& r = model.instrument_reaction(k);
    force += r.force;
    torque += r.torque + model.instrument_pose(k).translation().cross(r.force);
  }
  const Eigen::Vector3d got(total.wrench.force.x, total.wrench.force.y, total.wrench.force.z);
  const Eigen::Vector3d got_torque(total.wrench.torque.x, total.wrench.torque.y, total.wrench.torque.z);
  EXPECT_EQ(total.header.frame_id, "liver");
  EXPECT_LE((got - force).norm(), 0.03 * force.norm() + 2e-4) << stage << ": total " << got.transpose();
  EXPECT_LE((got_torque - torque).norm(), 0.03 * torque.norm() + 2e-4 * 0.015) << stage << ": total torque " << got_torque.transpose();
}

TEST(Instruments, GrasperAndProbeFromTheirOwnFramesMatchTheCore) {
  ros::NodeHandle nh;
  auto s1 = nh.subscribe<liver_sim::SimulationStatus>(
      "liver_sim/status", 10, boost::function<void(const liver_sim::SimulationStatus::ConstPtr&)>(
                                  [](const liver_sim::SimulationStatus::ConstPtr& m) { status = *m; }));
  std::vector<ros::Subscriber> wrench_subs;
  for (std::string name : {"jaws", "tip"})
    wrench_subs.push_back(nh.subscribe<geometry_msgs::WrenchStamped>(
        "liver_sim/instruments/" + name + "/wrench", 10,
        boost::function<void(const geometry_msgs::WrenchStamped::ConstPtr&)>(
            [name](const geometry_msgs::WrenchStamped::ConstPtr& m) { wrenches[name] = *m; })));
  auto s4 = nh.subscribe<geometry_msgs::WrenchStamped>(
      "liver_sim/wrench", 10, boost::function<void(const geometry_msgs::WrenchStamped::ConstPtr&)>(
                                  [](const geometry_msgs::WrenchStamped::ConstPtr& m) { total = *m; }));
  auto s3 = nh.subscribe<visualization_msgs::MarkerArray>(
      "liver_sim/instruments", 10, boost::function<void(const visualization_msgs::MarkerArray::ConstPtr&)>(
                                       [](const visualization_msgs::MarkerArray::ConstPtr& m) { markers = *m; }));
  ros::Publisher command = nh.advertise<liver_sim::InstrumentCommand>("instrument_command", 10);

  // Jaws just above the top face near one edge (their 2.5 mm reach takes several nodes), and a
  // 2 mm probe pressed 1.5 mm into the top face, its frame tilted 30 degrees about x.
  Tracker tracker;
  Eigen::Isometry3d jaws = Eigen::Isometry3d::Identity(), tip = Eigen::Isometry3d::Identity();
  jaws.translation() << 0.004, 0.0075, kL + 0.0005;
  tip.linear() = Eigen::AngleAxisd(M_PI / 6, Eigen::Vector3d::UnitX()).toRotationMatrix();
  tip.translation() << 0.011, 0.0075, kL + 0.002 - 0.0015;
  tracker.set("jaws_tf", jaws);
  tracker.set("tip_tf", tip);
  ASSERT_TRUE(wait_for(
      [&] { return status.header.stamp.toSec() > 0 && command.getNumSubscribers() > 0 && tracker.heard(); }, 60.0));

  // The same scene in the core.
  const liver_sim::Scene scene =
      liver_sim::load_scene(std::string(LIVER_SIM_SOURCE_DIR) + "/config/scenes/probe_cube.yaml", {"contact.friction=0"});
  liver_sim::LiverModel model(liver_sim::load_scene_mesh(scene), scene);
  InstrumentOptions g, p;
  g.name = "jaws";
  g.type = InstrumentOptions::Type::Grasper;
  g.radius = 0.0025;
  p.name = "tip";
  p.type = InstrumentOptions::Type::Probe;
  p.radius = 0.002;
  auto place = [](InstrumentOptions& o, const Eigen::Isometry3d& pose) {
    o.position = pose.translation();
    o.orientation = Eigen::Quaterniond(pose.linear());
  };
  place(g, jaws);
  place(p, tip);
  const int kg = model.add_instrument(g), kp = model.add_instrument(p);
  solve(model);

  ros::Time sent = ros::Time::now();
  liver_sim::InstrumentCommand c;
  c.name = "jaws";
  c.type = "grasper";
  c.radius = g.radius;
  c.frame = "jaws_tf";
  command.publish(c);
  c = liver_sim::InstrumentCommand();
  c.name = "tip";
  c.type = "probe";
  c.radius = p.radius;
  c.frame = "tip_tf";
  command.publish(c);
  liver_sim::SimulationStatus s = settled(sent);
  ASSERT_EQ(s.instrument_names.size(), 2u) << "jaws and tip posed; the default tool not";
  std::map<std::string, int> contacts;
  for (size_t i = 0; i < s.instrument_names.size(); ++i) contacts[s.instrument_names[i]] = s.instrument_contacts[i];
  EXPECT_GT(contacts["tip"], 0);
  EXPECT_EQ(contacts["tip"], model.instrument_reaction(kp).contacts);
  expect_wrench("tip", model, kp, tip, "pressed");
  expect_total(model, "pressed");
  EXPECT_GT(model.instrument_reaction(kp).force.norm(), 1e-3) << "the probe presses";
  int adds = 0;
  for (const auto& m : markers.markers) adds += m.action == visualization_msgs::Marker::ADD;
  EXPECT_EQ(adds, 4 + 1) << "a grasper's two jaws, hinge pin and shaft, a probe's sphere";

  // Close, lift 2 mm, open: the tissue hangs on the jaws, then lets go.
  struct Stage {
    const char* name;
    bool closed;
    double lift;
  };
  for (const Stage& stage : {Stage{"closed", true, 0.0}, Stage{"lifted", true, 0.002}, Stage{"opened", false, 0.002}}) {
    sent = ros::Time::now();
    if (stage.lift != jaws.translation().z() - (kL + 0.0005)) {
      jaws.translation().z() = kL + 0.0005 + stage.lift;
      tracker.set("jaws_tf", jaws);
    }
    if (stage.closed != g.closed) {
      c = liver_sim::InstrumentCommand();
      c.name = "jaws";
      c.grasp = stage.closed;
      command.publish(c);
    }
    g.closed = stage.closed;
    place(g, jaws);
    model.update_instrument(kg, g);
    solve(model);
    s = settled(sent);
    expect_wrench("jaws", model, kg, jaws, stage.name);
    expect_wrench("tip", model, kp, tip, stage.name);
    expect_total(model, stage.name);
    if (stage.lift > 0 && stage.closed) {
      EXPECT_LT(model.instrument_reaction(kg).force.z(), -1e-3) << "the lifted tissue pulls the jaws down";
    }
  }
  EXPECT_EQ(model.instrument_reaction(kg).contacts, 0) << "opened jaws hold nothing";

  // Removed, both leave the scene (their frames are still broadcast).
  sent = ros::Time::now();
  for (std::string name : {"jaws", "tip"}) {
    c = liver_sim::InstrumentCommand();
    c.name = name;
    c.remove = true;
    command.publish(c);
  }
  EXPECT_TRUE(settled(sent).instrument_names.empty());
}

// Each refused command names its field, is counted, and changes nothing (no step follows it).
TEST(Instruments, RefusalsNameTheFieldAndChangeNothing) {
  ros::NodeHandle nh;
  auto sub = nh.subscribe("liver_sim/status", 100, on_status_with_text);
  ros::Publisher command = nh.advertise<liver_sim::InstrumentCommand>("instrument_command", 10);
  ASSERT_TRUE(wait_for([&] { return command.getNumSubscribers() > 0 && status.state == "idle"; }, 60.0));
  const liver_sim::SimulationStatus before = status;
  auto refused = [&](const liver_sim::InstrumentCommand& c, const std::string& field) {
    const ros::Time now = ros::Time::now();
    wait_for([&] { return status.header.stamp > now; }, 10.0);  // a status after the last refusal
    texts.clear();
    const uint32_t n = status.rejected_inputs;
    command.publish(c);
    ASSERT_TRUE(wait_for([&] { return status.rejected_inputs == n + 1; }, 10.0)) << field;
    auto names = [&](const std::string& t) { return t.find(field) != std::string::npos; };
    EXPECT_TRUE(wait_for([&] { return std::any_of(texts.begin(), texts.end(), names); }, 5.0)) << field;
  };
  liver_sim::InstrumentCommand c;
  c.name = "hook";
  c.type = "scalpel";
  refused(c, "type");
  c.type = "probe";
  c.radius = -0.001;
  refused(c, "radius");
  c.radius = std::nan("");
  refused(c, "radius");
  c = liver_sim::InstrumentCommand();
  c.name = "sucker";
  c.type = "tube";
  c.suction = -100;
  refused(c, "suction");
  // A frame tf does not know yet is not refused: the instrument waits for it (instrument_tf_late.test).
  c = liver_sim::InstrumentCommand();
  c.name = "bad name";
  c.type = "probe";
  refused(c, "name");
  c.name = "ghost";
  c.type = "";
  refused(c, "ghost");  // a change of an instrument that does not exist
  wait_for([] { return false; }, 0.5);
  EXPECT_EQ(status.step, before.step) << "a refused command made the model step";
  EXPECT_EQ(status.instrument_names, before.instrument_names);
}

// The default tool, posed on its topic: a re-sent pose costs no step; when the poses stop it is
// withdrawn after ~pose_timeout (1 s here); once removed, its poses are not heard.
TEST(Instruments, StalePosesWithdrawAndRemovedStaysOut) {
  ros::NodeHandle nh;
  dynamic_reconfigure::Reconfigure timeout;
  dynamic_reconfigure::DoubleParameter p;
  p.name = "pose_timeout";
  p.value = 1.0;
  timeout.request.config.doubles.push_back(p);
  ASSERT_TRUE(ros::service::call("liver_sim/set_parameters", timeout));
  auto sub = nh.subscribe<liver_sim::SimulationStatus>(
      "liver_sim/status", 10, boost::function<void(const liver_sim::SimulationStatus::ConstPtr&)>(
                                  [](const liver_sim::SimulationStatus::ConstPtr& m) { status = *m; }));
  ros::Publisher pose_pub = nh.advertise<geometry_msgs::PoseStamped>("instruments/tool/pose", 1);
  ros::Publisher command = nh.advertise<liver_sim::InstrumentCommand>("instrument_command", 10);
  ASSERT_TRUE(wait_for(
      [&] { return pose_pub.getNumSubscribers() > 0 && command.getNumSubscribers() > 0 && status.state == "idle"; }, 60.0));
  auto has_tool = [] {
    return std::find(status.instrument_names.begin(), status.instrument_names.end(), "tool") != status.instrument_names.end();
  };
  geometry_msgs::PoseStamped pose;
  pose.header.frame_id = "liver";
  pose.pose.position.x = 0.0075;
  pose.pose.position.y = 0.003;
  pose.pose.position.z = kL + 0.003 - 0.001;  // the 3 mm rod 1 mm into the top face
  pose.pose.orientation.w = 1;
  bool streaming = true;
  const ros::WallTimer tracker = nh.createWallTimer(ros::WallDuration(0.05), [&](const ros::WallTimerEvent&) {
    if (!streaming) return;
    pose.header.stamp = ros::Time::now();
    pose_pub.publish(pose);
  });
  const liver_sim::SimulationStatus pressed = settled(ros::Time::now());
  ASSERT_TRUE(has_tool()) << "the streamed tool is in the scene";
  wait_for([] { return false; }, 1.0);
  EXPECT_EQ(status.step, pressed.step) << "the same pose, re-sent 20 times a second, made the model step";
  streaming = false;
  EXPECT_TRUE(wait_for([&] { return !has_tool(); }, 30.0)) << "the tool stayed after its poses stopped";
  streaming = true;
  EXPECT_TRUE(wait_for([&] { return has_tool(); }, 30.0)) << "a fresh pose brings it back";
  liver_sim::InstrumentCommand c;
  c.name = "tool";
  c.remove = true;
  command.publish(c);
  EXPECT_TRUE(wait_for([&] { return !has_tool(); }, 30.0)) << "removed";
  const uint32_t rejected = status.rejected_inputs;
  settled(ros::Time::now());
  EXPECT_FALSE(has_tool()) << "a pose after the removal brought the tool back";
  EXPECT_EQ(status.rejected_inputs, rejected) << "poses for a removed instrument are not heard, not refused";
}

// An instrument removed and declared again with the same name and type between two frames (the
// two commands back to back) takes up its old slot in the model, and stays in the scene: its
// frame does not move, so no new pose would bring it back (the slot was disabled as retired).
TEST(Instruments, RemovedAndDeclaredAgainInOneFrameStaysIn) {
  ros::NodeHandle nh;
  auto sub = nh.subscribe("liver_sim/status", 100, on_status_with_text);
  ros::Publisher command = nh.advertise<liver_sim::InstrumentCommand>("instrument_command", 10);
  ASSERT_TRUE(wait_for([&] { return command.getNumSubscribers() > 0 && status.header.stamp.toSec() > 0; }, 60.0));
  Tracker tracker;
  Eigen::Isometry3d held = Eigen::Isometry3d::Identity();
  held.translation() << 0.0075, 0.0075, kL + 0.01;  // 1 cm above the cube: no contact
  tracker.set("retractor_frame", held);
  ASSERT_TRUE(wait_for([&] { return tracker.heard(); }, 30.0));
  auto in_scene = [] {
    return std::count(status.instrument_names.begin(), status.instrument_names.end(), "retractor") == 1;
  };
  liver_sim::InstrumentCommand declare;
  declare.name = "retractor";
  declare.type = "shaft";
  declare.frame = "retractor_frame";
  command.publish(declare);
  ASSERT_TRUE(wait_for(in_scene, 30.0)) << "declared on its frame";
  const uint32_t rejected = status.rejected_inputs;
  liver_sim::InstrumentCommand remove;
  remove.name = "retractor";
  remove.remove = true;
  command.publish(remove);
  command.publish(declare);
  const ros::Time sent = ros::Time::now();
  ASSERT_TRUE(wait_for([&] { return status.header.stamp > sent + ros::Duration(1.0); }, 30.0));
  EXPECT_TRUE(in_scene()) << "withdrawn after being declared again";
  EXPECT_EQ(status.rejected_inputs, rejected);
  command.publish(remove);
  EXPECT_TRUE(wait_for([&] { return !in_scene(); }, 30.0)) << "removed";
}

// Seventeen instruments, one after another, each declared, posed, and removed: more names than
// the model has slots (16) over the node's life, never more than two at once. Each is taken
// into the scene and none is refused: a new one takes the slot of one withdrawn. With a slot
// kept for every name ever declared, the first name past the model's 16 slots (probe12 after
// this suite's earlier tests) was refused at every frame (checked).
TEST(Instruments, SlotsOfRemovedInstrumentsAreTakenAgain) {
  ros::NodeHandle nh;
  auto sub = nh.subscribe("liver_sim/status", 100, on_status_with_text);
  ros::Publisher command = nh.advertise<liver_sim::InstrumentCommand>("instrument_command", 10);
  ASSERT_TRUE(wait_for([&] { return command.getNumSubscribers() > 0 && status.header.stamp.toSec() > 0; }, 60.0));
  const uint32_t rejected = status.rejected_inputs;
  for (int k = 0; k < liver_sim::kMaxInstruments + 1; ++k) {
    const std::string name = "probe" + std::to_string(k);
    auto in_scene = [&] {
      return std::count(status.instrument_names.begin(), status.instrument_names.end(), name) == 1;
    };
    liver_sim::InstrumentCommand c;
    c.name = name;
    c.type = k % 2 ? "probe" : "shaft";  // a slot of the other type is taken too
    command.publish(c);
    ros::Publisher pose_pub = nh.advertise<geometry_msgs::PoseStamped>("instruments/" + name + "/pose", 1, true);
    geometry_msgs::PoseStamped pose;
    pose.header.frame_id = "liver";
    pose.header.stamp = ros::Time::now();
    pose.pose.position.x = pose.pose.position.y = 0.0075;
    pose.pose.position.z = kL + 0.01;  // 1 cm above the cube
    pose.pose.orientation.w = 1;
    pose_pub.publish(pose);  // latched: heard once the node subscribes
    ASSERT_TRUE(wait_for(in_scene, 30.0)) << name << ": " << status.text;
    c = liver_sim::InstrumentCommand();
    c.name = name;
    c.remove = true;
    command.publish(c);
    ASSERT_TRUE(wait_for([&] { return !in_scene(); }, 30.0)) << name << " removed";
  }
  EXPECT_EQ(status.rejected_inputs, rejected) << status.text;
}

// Poses stamped in a tracker frame that tf updates at 50 Hz: each waits for its transform (up
// to ~instrument_tf_timeout) instead of being refused as an extrapolation into the future.
// With ~instrument_tf_timeout 0 every one of them is refused and this test fails.
TEST(Instruments, PosesInAMovingTrackerFrameAreAccepted) {
  ros::NodeHandle nh;
  auto sub = nh.subscribe("liver_sim/status", 100, on_status_with_text);
  ros::Publisher command = nh.advertise<liver_sim::InstrumentCommand>("instrument_command", 10);
  ros::Publisher pose_pub = nh.advertise<geometry_msgs::PoseStamped>("instruments/needle/pose", 10);
  ASSERT_TRUE(wait_for([&] { return command.getNumSubscribers() > 0 && status.header.stamp.toSec() > 0; }, 60.0));
  liver_sim::InstrumentCommand c;
  c.name = "needle";
  c.type = "shaft";
  c.radius = 0.001;
  command.publish(c);
  ASSERT_TRUE(wait_for([&] { return pose_pub.getNumSubscribers() > 0; }, 10.0));
  // The tracker drifts 1 mm/s along y; the needle stays 5 mm above the cube in the model frame.
  Tracker tracker;
  const ros::WallTime start = ros::WallTime::now();
  const ros::WallTimer timer = nh.createWallTimer(ros::WallDuration(0.01), [&](const ros::WallTimerEvent&) {
    Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
    t.translation() << 0, 0.001 * (ros::WallTime::now() - start).toSec(), 0;
    tracker.set("tracker", t);
  });
  auto send = [&] {  // stamped now: the transform for that time comes a little later
    geometry_msgs::PoseStamped p;
    p.header.frame_id = "tracker";
    p.header.stamp = ros::Time::now();
    p.pose.position.x = 0.0075;
    p.pose.position.y = 0.0075 - tracker.get("tracker").translation().y();
    p.pose.position.z = kL + 0.005;
    p.pose.orientation.w = 1;
    pose_pub.publish(p);
    wait_for([] { return false; }, 0.02);
  };
  auto has_needle = [] {
    return std::find(status.instrument_names.begin(), status.instrument_names.end(), "needle") != status.instrument_names.end();
  };
  // Until the node's tf listener has the new tracker's frames (poses older than its first
  // transform are refused, rightly), then a hundred poses at 50 Hz.
  ASSERT_TRUE(wait_for([&] { return send(), has_needle(); }, 10.0));
  wait_for([] { return false; }, 0.3);
  const uint32_t rejected = status.rejected_inputs;
  for (int i = 0; i < 100; ++i) send();
  wait_for([] { return false; }, 0.5);
  EXPECT_EQ(status.rejected_inputs, rejected) << (texts.empty() ? "" : texts.back());
  EXPECT_TRUE(has_needle());
}

}  // namespace

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "instruments_test");
  return RUN_ALL_TESTS();
}
