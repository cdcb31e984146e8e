#include "instrument_bridge.h"

#include <geometry_msgs/TransformStamped.h>
#include <geometry_msgs/WrenchStamped.h>
#include <tf2_geometry_msgs/tf2_geometry_msgs.h>
#include <visualization_msgs/MarkerArray.h>

#include <boost/function.hpp>
#include <vector>

#include "instrument_markers.h"
#include "msg_conversion.h"

namespace liver_sim {

InstrumentBridge::InstrumentBridge(ros::NodeHandle& nh, ros::NodeHandle& pnh, tf2_ros::Buffer& tf,
                                   TrackingSession& session, const std::string& frame_id, double tf_timeout)
    : nh_(nh), pnh_(pnh), tf_(tf), session_(session), frame_id_(frame_id), tf_timeout_(tf_timeout) {
  command_sub_ = nh_.subscribe("instrument_command", 10, &InstrumentBridge::on_command, this);
  wrench_pub_ = pnh_.advertise<geometry_msgs::WrenchStamped>("wrench", 10);
  marker_pub_ = pnh_.advertise<visualization_msgs::MarkerArray>("instruments", 1, true);
  std::lock_guard<std::mutex> lock(mutex_);
  for (const InstrumentSlots::Slot& s : session_.instruments()) open(s.name);
}

void InstrumentBridge::open(const std::string& name) {
  if (topics_.count(name)) return;
  Topics& t = topics_[name];
  const boost::function<void(const geometry_msgs::PoseStamped::ConstPtr&)> cb =
      [this, name](const geometry_msgs::PoseStamped::ConstPtr& m) { on_pose(name, m); };
  t.pose_sub = nh_.subscribe<geometry_msgs::PoseStamped>("instruments/" + name + "/pose", 1, cb);
  t.wrench_pub = pnh_.advertise<geometry_msgs::WrenchStamped>("instruments/" + name + "/wrench", 10);
}

void InstrumentBridge::on_command(const InstrumentCommand::ConstPtr& msg) {
  const InstrumentRequest request = to_request(*msg);
  if (!session_.submit(request) || request.remove) return;
  // Trackers start in any order: an instrument whose frame tf does not know yet waits out of the
  // scene, said in ~status until it joins, at the first frame that finds its frame.
  if (!request.frame.empty() && !tf_.canTransform(frame_id_, request.frame, ros::Time(0)))
    session_.notices().tell("instrument " + request.name + ": tf frame '" + request.frame +
                            "' not known yet; out of the scene until it is");
  std::lock_guard<std::mutex> lock(mutex_);
  open(request.name);
}

void InstrumentBridge::on_pose(const std::string& name, const geometry_msgs::PoseStamped::ConstPtr& msg) {
  const std::string topic = "instruments/" + name + "/pose";
  geometry_msgs::PoseStamped p = *msg;
  const std::string error = pose_error(p.pose);
  if (!error.empty()) return session_.refuse(topic + ": " + error);
  if (!p.header.frame_id.empty() && p.header.frame_id != frame_id_) {
    try {
      p = tf_.transform(p, frame_id_, ros::Duration(tf_timeout_));
    } catch (const tf2::TransformException& e) {
      return session_.refuse(topic + " in frame '" + msg->header.frame_id + "': " + e.what());
    }
  }
  InstrumentPose pose;
  pose.name = name;
  to_position_orientation(p.pose, pose.position, pose.orientation);
  pose.stamp = to_stamp(msg->header.stamp);
  pose.received = to_stamp(ros::Time::now());
  session_.submit(pose);
}

void InstrumentBridge::poll_frames() {
  for (const InstrumentSlots::Slot& s : session_.instruments()) {
    if (s.frame.empty()) continue;
    try {
      const geometry_msgs::TransformStamped t = tf_.lookupTransform(frame_id_, s.frame, ros::Time(0));
      session_.submit(FramePose{s.name, s.frame, to_isometry(t.transform), to_stamp(t.header.stamp)});
    } catch (const tf2::TransformException& e) {
      ROS_WARN_THROTTLE(5.0, "liver_sim: instrument %s, frame %s: %s", s.name.c_str(), s.frame.c_str(), e.what());
    }
  }
}

void InstrumentBridge::after_frame(bool redrawn) {
  markers_due_ |= redrawn;
  std::vector<Topics> closed;  // destroyed after the lock: a subscriber waits for its callbacks
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const std::vector<InstrumentSlots::Slot> slots = session_.instruments();
    for (auto it = topics_.begin(); it != topics_.end();) {
      const bool declared =
          std::any_of(slots.begin(), slots.end(), [&](const InstrumentSlots::Slot& s) { return s.name == it->first; });
      if (declared) {
        ++it;
        continue;
      }
      closed.push_back(std::move(it->second));
      it = topics_.erase(it);
    }
  }
}

void InstrumentBridge::publish(const std_msgs::Header& header) {
  const LiverModel& model = session_.model();
  const std::vector<InstrumentSlots::Slot> slots = session_.instruments();
  Eigen::Vector3d force = Eigen::Vector3d::Zero(), torque = Eigen::Vector3d::Zero();
  std::vector<geometry_msgs::TransformStamped> tips;
  std::lock_guard<std::mutex> lock(mutex_);
  for (const InstrumentSlots::Slot& s : slots) {
    if (s.index < 0) continue;
    const InstrumentReaction& r = model.instrument_reaction(s.index);
    const Eigen::Isometry3d& P = model.instrument_pose(s.index);
    const auto topics = topics_.find(s.name);
    if (topics != topics_.end() && P.matrix() != topics->second.drawn.matrix()) {  // a scene trajectory moves it too
      topics->second.drawn = P;
      markers_due_ = true;
    }
    force += r.force;
    torque += r.torque + P.translation().cross(r.force);
    geometry_msgs::WrenchStamped w;
    w.header.stamp = header.stamp;
    w.header.frame_id = s.frame.empty() ? s.name + "_tip" : s.frame;
    w.wrench.force = to_vector(P.linear().transpose() * r.force);
    w.wrench.torque = to_vector(P.linear().transpose() * r.torque);
    if (topics != topics_.end()) topics->second.wrench_pub.publish(w);
    if (s.frame.empty() && model.instrument(s.index).enabled && tip_stamps_[w.header.frame_id] != header.stamp) {
      tip_stamps_[w.header.frame_id] = header.stamp;
      geometry_msgs::TransformStamped t;
      t.header = header;
      t.child_frame_id = w.header.frame_id;
      t.transform = to_transform(P);
      tips.push_back(t);
    }
  }
  if (!tips.empty()) tip_broadcaster_.sendTransform(tips);
  geometry_msgs::WrenchStamped total;
  total.header = header;
  total.wrench.force = to_vector(force);
  total.wrench.torque = to_vector(torque);
  wrench_pub_.publish(total);
  if (markers_due_) marker_pub_.publish(instrument_markers(model, slots, header));
  markers_due_ = false;
}

}  // namespace liver_sim
