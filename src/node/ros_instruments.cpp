#include <algorithm>
#include "ros_instruments.h"

#include <geometry_msgs/TransformStamped.h>
#include <geometry_msgs/WrenchStamped.h>
#include <tf2_geometry_msgs/tf2_geometry_msgs.h>

#include <boost/bind/bind.hpp>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace liver_sim {
namespace {

const char* type_name(InstrumentOptions::Type t) {
  switch (t) {
    case InstrumentOptions::Type::Probe: return "probe";
    case InstrumentOptions::Type::Shaft: return "shaft";
    case InstrumentOptions::Type::Tube: return "tube";
    case InstrumentOptions::Type::Grasper: return "grasper";
  }
  return "";
}

std::optional<InstrumentOptions::Type> parse_type(const std::string& s) {
  for (auto t : {InstrumentOptions::Type::Probe, InstrumentOptions::Type::Shaft, InstrumentOptions::Type::Tube,
                 InstrumentOptions::Type::Grasper})
    if (s == type_name(t)) return t;
  return std::nullopt;
}

// A tf frame's or a scene instrument's name as a topic name (instruments/<name>/pose).
std::string topic_name(const std::string& name) {
  std::string s = name;
  for (char& c : s)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_')) c = '_';
  return s;
}

// Names become topic names (instruments/<name>/pose).
std::string name_error(const std::string& name) {
  if (name.empty() || name.size() > 32) return "name must have 1 to 32 characters";
  for (char c : name)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_'))
      return "name '" + name + "' may hold letters, digits and '_' only";
  return "";
}

bool finite(const geometry_msgs::Pose& p) {
  return std::isfinite(p.position.x) && std::isfinite(p.position.y) && std::isfinite(p.position.z) &&
         std::isfinite(p.orientation.x) && std::isfinite(p.orientation.y) && std::isfinite(p.orientation.z) &&
         std::isfinite(p.orientation.w);
}

Eigen::Isometry3d to_eigen(const geometry_msgs::Transform& t) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::Quaterniond(t.rotation.w, t.rotation.x, t.rotation.y, t.rotation.z).normalized().toRotationMatrix();
  T.translation() = Eigen::Vector3d(t.translation.x, t.translation.y, t.translation.z);
  return T;
}

geometry_msgs::Vector3 to_msg(const Eigen::Vector3d& v) {
  geometry_msgs::Vector3 m;
  m.x = v.x();
  m.y = v.y();
  m.z = v.z();
  return m;
}

geometry_msgs::Pose to_pose(const Eigen::Isometry3d& P) {
  geometry_msgs::Pose p;
  const Eigen::Quaterniond q(P.linear());
  p.position.x = P.translation().x();
  p.position.y = P.translation().y();
  p.position.z = P.translation().z();
  p.orientation.x = q.x();
  p.orientation.y = q.y();
  p.orientation.z = q.z();
  p.orientation.w = q.w();
  return p;
}

}  // namespace

RosInstruments::RosInstruments(ros::NodeHandle& nh, ros::NodeHandle& pnh, tf2_ros::Buffer& tf, LiverModel& model,
                               const Settings& settings, std::function<void(const std::string&)> reject,
                               std::function<void(const std::string&)> warn)
    : nh_(nh), pnh_(pnh), tf_(tf), settings_(settings), reject_(std::move(reject)), warn_(std::move(warn)) {
  if (!(settings_.tf_timeout >= 0 && settings_.tf_timeout <= 1))
    throw std::invalid_argument("~instrument_tf_timeout must be in [0, 1] s");
  if (!(settings_.pose_timeout >= 0)) throw std::invalid_argument("~pose_timeout must be >= 0 s");
  settings_.tool.name = "tool";
  settings_.tool.enabled = false;
  const std::string tool_error = validate(settings_.tool);
  if (!tool_error.empty()) throw std::invalid_argument("~instrument_radius, ~instrument_length: " + tool_error);
  command_sub_ = nh_.subscribe("instrument_command", 10, &RosInstruments::on_command, this);
  wrench_pub_ = pnh_.advertise<geometry_msgs::WrenchStamped>("wrench", 10);
  marker_pub_ = pnh_.advertise<visualization_msgs::MarkerArray>("instruments", 1, true);
  std::lock_guard<std::mutex> lock(mutex_);
  // The scene's instruments keep their names in the model; ROS knows them by topic names.
  for (int i = 0; i < model.num_instruments(); ++i) {
    const std::string name = topic_name(model.instrument(i).name).substr(0, 32);
    if (tracked_.count(name)) throw std::invalid_argument("scene instruments '" + name + "': two names give one topic name");
    Tracked& t = track(name, model.instrument(i), "");
    t.index = i;
    t.shape_changed = false;
  }
  std::vector<std::pair<std::string, std::string>> declared;
  if (!tracked_.count("tool")) declared.emplace_back("tool", "");  // a scene's own `tool` takes the name
  for (const std::string& frame : settings_.frames) declared.emplace_back(topic_name(frame), frame);
  for (const auto& [name, frame] : declared) {
    const std::string error = name_error(name);
    if (!error.empty()) throw std::invalid_argument("~instrument_frames: " + error);
    if (tracked_.count(name)) throw std::invalid_argument("~instrument_frames: the instrument name '" + name + "' is taken");
    InstrumentOptions shape = settings_.tool;
    shape.name = name;
    track(name, shape, frame);
  }
  if (static_cast<int>(tracked_.size()) > kMaxInstruments)
    throw std::invalid_argument("more than " + std::to_string(kMaxInstruments) + " instruments");
}

RosInstruments::Tracked& RosInstruments::track(const std::string& name, const InstrumentOptions& shape,
                                               const std::string& frame) {
  Tracked& t = tracked_[name];
  t.shape = shape;
  t.frame = frame;
  const boost::function<void(const geometry_msgs::PoseStamped::ConstPtr&)> cb =
      [this, name](const geometry_msgs::PoseStamped::ConstPtr& m) { on_pose(name, m); };
  t.pose_sub = nh_.subscribe<geometry_msgs::PoseStamped>("instruments/" + name + "/pose", 1, cb);
  t.wrench_pub = pnh_.advertise<geometry_msgs::WrenchStamped>("instruments/" + name + "/wrench", 10);
  return t;
}

std::string RosInstruments::merge(const InstrumentCommand& c, InstrumentOptions& shape) const {
  using Type = InstrumentOptions::Type;
  const std::string k = "instrument_command " + c.name + ": ";
  if (!c.type.empty()) {
    const std::optional<Type> type = parse_type(c.type);
    if (!type) return k + "type '" + c.type + "' is not probe, shaft, tube or grasper";
    InstrumentOptions declared;
    declared.name = shape.name;
    declared.type = *type;
    declared.enabled = false;  // until its first pose
    shape = declared;
  }
  // Zero keeps a value; the bounds are the core's (validate below names the field).
  const std::pair<const char*, double> sizes[] = {
      {"radius", c.radius}, {"length", c.length}, {"inner_radius", c.inner_radius}, {"outer_radius", c.outer_radius}};
  for (const auto& [field, value] : sizes)
    if (!std::isfinite(value) || value < 0) return k + field + " must be finite and > 0 (0 keeps the current value)";
  if (c.radius > 0) shape.radius = c.radius;
  if (c.length > 0) shape.length = c.length;
  if (c.inner_radius > 0) shape.inner_radius = c.inner_radius;
  if (c.outer_radius > 0) shape.outer_radius = c.outer_radius;
  if (shape.type == Type::Tube) {
    if (!std::isfinite(c.suction)) return k + "suction must be finite";
    shape.suction = c.suction;
  }
  if (shape.type == Type::Grasper) shape.closed = c.grasp;
  const std::string error = validate(shape);
  return error.empty() ? "" : k + error;
}

void RosInstruments::on_command(const InstrumentCommand::ConstPtr& msg) {
  const InstrumentCommand& c = *msg;
  std::string error = name_error(c.name);
  if (!error.empty()) return reject_("instrument_command: " + error);
  // A frame tf does not know within the timeout is refused: a typo would otherwise hold the
  // instrument out of the scene without a word.
  if (!c.remove && !c.frame.empty()) {
    const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(settings_.tf_timeout);
    while (!tf_.canTransform(settings_.frame_id, c.frame, ros::Time(0)) && ros::WallTime::now() < end)
      ros::WallDuration(0.005).sleep();
    if (!tf_.canTransform(settings_.frame_id, c.frame, ros::Time(0), &error))
      return reject_("instrument_command " + c.name + ": frame '" + c.frame + "' unknown to tf (" + error + ")");
    error.clear();
  }
  std::optional<Tracked> dropped;  // destroyed after the lock: its subscriber waits for its callbacks
  std::unique_lock<std::mutex> lock(mutex_);
  const auto it = tracked_.find(c.name);
  const bool exists = it != tracked_.end() && !it->second.removed;
  if (c.remove) {
    if (!exists) {
      lock.unlock();
      return reject_("instrument_command: no instrument '" + c.name + "' to remove");
    }
    it->second.removed = true;
    return;
  }
  if (!exists && c.type.empty()) error = "no instrument '" + c.name + "' to change; a type declares one";
  int count = 0;
  for (const auto& [name, t] : tracked_) count += !t.removed;
  if (!exists && count >= kMaxInstruments) error = "at most " + std::to_string(kMaxInstruments) + " instruments";
  InstrumentOptions shape = exists ? it->second.shape : InstrumentOptions{};
  if (!exists) shape.name = c.name;  // an existing one keeps its name in the model
  if (error.empty()) error = merge(c, shape);
  if (!error.empty()) {
    lock.unlock();
    return reject_(error.rfind("instrument_command", 0) == 0 ? error : "instrument_command " + c.name + ": " + error);
  }
  if (!exists) {
    if (it != tracked_.end()) {  // removed, not yet applied: declared anew
      if (it->second.index >= 0) retired_.push_back(it->second.index);
      dropped = std::move(it->second);
      tracked_.erase(it);
    }
    track(c.name, shape, c.frame);
    return;
  }
  Tracked& t = it->second;
  t.shape = shape;
  t.shape_changed = true;
  // A declaration sets the pose source (empty frame: the topic); a change keeps it unless named.
  const std::string frame = c.type.empty() && c.frame.empty() ? t.frame : c.frame;
  if (frame != t.frame) {
    t.frame = frame;
    t.pose.reset();  // until the new source's first pose
    t.pose_changed = true;
  }
}

void RosInstruments::on_pose(const std::string& name, const geometry_msgs::PoseStamped::ConstPtr& msg) {
  const std::string topic = "instruments/" + name + "/pose";
  if (!finite(msg->pose)) return reject_(topic + ": NaN or infinite values");
  geometry_msgs::PoseStamped p = *msg;
  // An orientation left at zeros (unset) is the identity: the instrument points up its frame's z.
  auto& o = p.pose.orientation;
  if (o.x == 0 && o.y == 0 && o.z == 0 && o.w == 0) o.w = 1;
  if (!(std::abs(Eigen::Vector4d(o.x, o.y, o.z, o.w).norm() - 1) < 1e-3))
    return reject_(topic + ": orientation is not a unit quaternion");
  if (!p.header.frame_id.empty() && p.header.frame_id != settings_.frame_id) {
    try {
      p = tf_.transform(p, settings_.frame_id, ros::Duration(settings_.tf_timeout));
    } catch (const tf2::TransformException& e) {
      return reject_(topic + " in frame '" + msg->header.frame_id + "': " + e.what());
    }
  }
  const Eigen::Quaterniond q = Eigen::Quaterniond(o.w, o.x, o.y, o.z).normalized();
  std::unique_lock<std::mutex> lock(mutex_);
  const auto it = tracked_.find(name);
  if (it == tracked_.end() || it->second.removed) return;
  if (!it->second.frame.empty()) {
    lock.unlock();
    return reject_(topic + ": the instrument follows tf frame '" + it->second.frame + "'");
  }
  // Refused on arrival, as the model would refuse it (a later pose may replace it before a frame).
  InstrumentOptions posed = it->second.shape;
  posed.position = Eigen::Vector3d(p.pose.position.x, p.pose.position.y, p.pose.position.z);
  posed.orientation = q;
  const std::string error = validate(posed);
  if (!error.empty()) {
    lock.unlock();
    return reject_(topic + ": " + error);
  }
  set_pose(it->second, make_pose(posed.position, q), msg->header.stamp, ros::Time::now());
}

void RosInstruments::set_pose(Tracked& t, const Eigen::Isometry3d& pose, const ros::Time& stamp,
                              const ros::Time& received) {
  // A re-sent pose changes nothing, so costs no step.
  if (!t.pose || t.pose->matrix() != pose.matrix() || t.stale) {
    t.pose = pose;
    t.pose_changed = true;
    t.stamp = stamp;
  }
  t.stale = false;
  t.received = received;
}

void RosInstruments::lookup_frame(const std::string& name, Tracked& t) {
  try {
    const geometry_msgs::TransformStamped s = tf_.lookupTransform(settings_.frame_id, t.frame, ros::Time(0));
    const Eigen::Isometry3d pose = to_eigen(s.transform);
    if (!pose.matrix().allFinite()) return reject_("instrument " + name + ": non-finite transform of " + t.frame);
    // A static frame (stamp zero) never goes stale; a moving one ages from when its transform
    // last advanced, on this computer's clock (the tracker's may differ).
    if (s.header.stamp.isZero()) {
      set_pose(t, pose, s.header.stamp, ros::Time());
    } else if (!t.pose || s.header.stamp != t.tf_stamp) {
      t.tf_stamp = s.header.stamp;
      set_pose(t, pose, s.header.stamp, ros::Time::now());
    }
  } catch (const tf2::TransformException& e) {
    ROS_WARN_THROTTLE(5.0, "liver_sim: instrument %s, frame %s: %s", name.c_str(), t.frame.c_str(), e.what());
  }
}

int RosInstruments::free_slot(const LiverModel& model) const {
  bool freed_now = false;
  for (int i = 0; i < model.num_instruments(); ++i) {
    if (std::any_of(tracked_.begin(), tracked_.end(), [i](const auto& named) { return named.second.index == i; }))
      continue;
    if (model.instrument_withdrawn(i)) return i;
    freed_now = true;
  }
  return freed_now ? kFreeNextFrame : -1;
}

int RosInstruments::model_slot(LiverModel& model, const InstrumentOptions& shape) {
  const int own = model.find_instrument(shape.name);
  if (own >= 0 && model.instrument(own).type == shape.type) return own;
  return model.find_instrument(shape.name + "." + type_name(shape.type));
}

bool RosInstruments::apply(LiverModel& model) {
  std::vector<Tracked> dropped;  // destroyed after the lock: a subscriber waits for its callbacks
  std::lock_guard<std::mutex> lock(mutex_);
  bool changed = false;
  reflected_stamp_ = ros::Time();
  const ros::Time now = ros::Time::now();
  for (auto it = tracked_.begin(); it != tracked_.end();) {
    const std::string& name = it->first;
    Tracked& t = it->second;
    if (t.removed) {
      if (t.index >= 0) retired_.push_back(t.index);
      dropped.push_back(std::move(t));
      it = tracked_.erase(it);
      continue;
    }
    if (!t.frame.empty()) lookup_frame(name, t);
    if (t.pose && !t.stale && settings_.pose_timeout > 0 && !t.received.isZero() &&
        (now - t.received).toSec() > settings_.pose_timeout) {
      t.stale = true;
      if (!settings_.hold_stale) {
        t.pose_changed = true;
        std::ostringstream why;
        why << "instrument " << name << ": no pose for " << settings_.pose_timeout << " s; withdrawn until the next";
        warn_(why.str());
      }
    }
    if (t.index >= 0 && !t.shape_changed && !t.pose_changed) {
      ++it;
      continue;
    }
    InstrumentOptions o = t.shape;
    if (t.pose) {  // ROS drives it: the pose replaces any trajectory of the scene
      o.trajectory.clear();
      o.position = t.pose->translation();
      o.orientation = Eigen::Quaterniond(t.pose->linear());
      o.enabled = !(t.stale && !settings_.hold_stale);
    } else if (t.frame.empty() && t.index >= 0 && model.instrument(t.index).type == o.type) {
      o.enabled = t.shape.enabled;  // the scene's own, or declared and not posed yet
    } else {
      o.enabled = false;
    }
    try {
      int slot = model_slot(model, o);
      if (slot < 0) {
        if (model.find_instrument(o.name) >= 0) o.name += std::string(".") + type_name(o.type);
        const int free = model.num_instruments() < kMaxInstruments ? -1 : free_slot(model);
        if (free == kFreeNextFrame) {  // out of the scene once a step has run without it
          changed = true;
          ++it;
          continue;
        }
        if (free >= 0) {
          model.replace_instrument(free, o);
          slot = free;
        } else {
          slot = model.add_instrument(o);
        }
      } else {
        o.name = model.instrument(slot).name;
        model.update_instrument(slot, o);
      }
      if (t.index >= 0 && t.index != slot) retired_.push_back(t.index);  // retyped
      t.index = slot;
      if (t.pose_changed && t.pose && t.stamp > reflected_stamp_) reflected_stamp_ = t.stamp;
      changed = true;
      markers_due_ = true;
    } catch (const std::invalid_argument& e) {
      reject_("instrument " + name + ": " + e.what());
    }
    t.shape_changed = t.pose_changed = false;
    ++it;
  }
  for (int i : retired_) {
    InstrumentOptions o = model.instrument(i);
    if (!o.enabled) continue;
    // Taken up again this frame: removed and declared anew with the same name and type.
    if (std::any_of(tracked_.begin(), tracked_.end(), [i](const auto& named) { return named.second.index == i; }))
      continue;
    o.enabled = false;
    model.update_instrument(i, o);
    changed = true;
    markers_due_ = true;
  }
  retired_.clear();
  return changed;
}

void RosInstruments::release_all(LiverModel& model) {
  std::lock_guard<std::mutex> lock(mutex_);
  for (auto& [name, t] : tracked_) {
    if (!t.pose || t.index < 0) continue;
    t.pose.reset();
    t.stale = false;
    InstrumentOptions o = model.instrument(t.index);
    o.enabled = false;
    model.update_instrument(t.index, o);
    markers_due_ = true;
  }
}

void RosInstruments::set_staleness(double pose_timeout, bool hold_stale) {
  std::lock_guard<std::mutex> lock(mutex_);
  settings_.pose_timeout = pose_timeout;
  if (settings_.hold_stale != hold_stale)
    for (auto& [name, t] : tracked_) t.pose_changed |= t.stale;  // held ones withdrawn, or back
  settings_.hold_stale = hold_stale;
}

std::string RosInstruments::frame_of(const std::string& name, const Tracked& t) const {
  return t.frame.empty() ? name + "_tip" : t.frame;
}

void RosInstruments::publish(const LiverModel& model, const std_msgs::Header& header) {
  std::lock_guard<std::mutex> lock(mutex_);
  Eigen::Vector3d force = Eigen::Vector3d::Zero(), torque = Eigen::Vector3d::Zero();
  std::vector<geometry_msgs::TransformStamped> tips;
  for (auto& [name, t] : tracked_) {
    if (t.index < 0) continue;
    const InstrumentReaction& r = model.instrument_reaction(t.index);
    const Eigen::Isometry3d& P = model.instrument_pose(t.index);
    if (P.matrix() != t.drawn.matrix()) {  // a scene trajectory moves it too
      t.drawn = P;
      markers_due_ = true;
    }
    force += r.force;
    torque += r.torque + P.translation().cross(r.force);
    geometry_msgs::WrenchStamped w;
    w.header.stamp = header.stamp;
    w.header.frame_id = frame_of(name, t);
    w.wrench.force = to_msg(P.linear().transpose() * r.force);
    w.wrench.torque = to_msg(P.linear().transpose() * r.torque);
    t.wrench_pub.publish(w);
    if (t.frame.empty() && model.instrument(t.index).enabled) {
      geometry_msgs::TransformStamped s;
      s.header = header;
      s.child_frame_id = w.header.frame_id;
      const geometry_msgs::Pose p = to_pose(P);
      s.transform.translation.x = p.position.x;
      s.transform.translation.y = p.position.y;
      s.transform.translation.z = p.position.z;
      s.transform.rotation = p.orientation;
      tips.push_back(s);
    }
  }
  if (!tips.empty()) tip_broadcaster_.sendTransform(tips);
  geometry_msgs::WrenchStamped total;
  total.header = header;
  total.wrench.force = to_msg(force);
  total.wrench.torque = to_msg(torque);
  wrench_pub_.publish(total);
  if (markers_due_) marker_pub_.publish(markers(model, header));
  markers_due_ = false;
}

void RosInstruments::fill_status(const LiverModel& model, SimulationStatus& status) const {
  std::lock_guard<std::mutex> lock(mutex_);
  for (const auto& [name, t] : tracked_) {
    if (t.index < 0 || !model.instrument(t.index).enabled) continue;
    status.instrument_names.push_back(name);
    status.instrument_contacts.push_back(model.instrument_reaction(t.index).contacts);
  }
}

// Each instrument as what it is, from its tip pose P (+z back along it): a probe's sphere, a
// shaft's rounded rod, a tube's wall around its darker lumen, a grasper's two jaws (apart when
// open) on its rod. Instruments out of the scene are not drawn.
visualization_msgs::MarkerArray RosInstruments::markers(const LiverModel& model, const std_msgs::Header& header) const {
  using visualization_msgs::Marker;
  visualization_msgs::MarkerArray a;
  Marker clear;
  clear.header = header;
  clear.ns = "instruments";
  clear.action = Marker::DELETEALL;
  a.markers.push_back(clear);
  int id = 0;
  auto part = [&](int type, const Eigen::Isometry3d& pose, const Eigen::Vector3d& scale, float grey, float alpha) {
    Marker m;
    m.header = header;
    m.ns = "instruments";
    m.id = id++;
    m.type = type;
    m.action = Marker::ADD;
    m.pose = to_pose(pose);
    m.scale.x = scale.x();
    m.scale.y = scale.y();
    m.scale.z = scale.z();
    m.color.r = m.color.g = grey;
    m.color.b = grey + 0.05f;
    m.color.a = alpha;
    a.markers.push_back(m);
  };
  using Type = InstrumentOptions::Type;
  for (const auto& [name, t] : tracked_) {
    if (t.index < 0 || !model.instrument(t.index).enabled) continue;
    const InstrumentOptions& o = model.instrument(t.index);
    const Eigen::Isometry3d& P = model.instrument_pose(t.index);
    const auto along = [&](double z) { return P * Eigen::Translation3d(0, 0, z); };
    switch (o.type) {
      case Type::Probe:
        part(Marker::SPHERE, P, Eigen::Vector3d::Constant(2 * o.radius), 0.75f, 1.0f);
        break;
      case Type::Shaft:
        part(Marker::SPHERE, P, Eigen::Vector3d::Constant(2 * o.radius), 0.75f, 1.0f);
        part(Marker::CYLINDER, along(0.5 * o.length), Eigen::Vector3d(2 * o.radius, 2 * o.radius, o.length), 0.75f, 1.0f);
        break;
      case Type::Tube:
        part(Marker::CYLINDER, along(0.5 * o.length), Eigen::Vector3d(2 * o.outer_radius, 2 * o.outer_radius, o.length),
             0.8f, 0.5f);
        part(Marker::CYLINDER, along(0.5 * o.length + 1e-4),
             Eigen::Vector3d(2 * o.inner_radius, 2 * o.inner_radius, o.length), 0.2f, 1.0f);
        break;
      case Type::Grasper: {
        // Jaws of twice the hold radius, tilted apart by 25 degrees when open.
        const double r = o.radius, tilt = o.closed ? 0.0 : 25.0 * M_PI / 180.0;
        for (int side : {-1, 1}) {
          const Eigen::Isometry3d jaw = P * Eigen::Translation3d(0, 0, r) * Eigen::AngleAxisd(side * tilt, Eigen::Vector3d::UnitY()) *
                                        Eigen::Translation3d(side * 0.25 * r, 0, -r);
          part(Marker::CUBE, jaw, Eigen::Vector3d(0.3 * r, 0.8 * r, 2 * r), 0.55f, 1.0f);
        }
        part(Marker::CYLINDER, along(r + 0.5 * o.length), Eigen::Vector3d(0.8 * r, 0.8 * r, o.length), 0.75f, 1.0f);
        break;
      }
    }
  }
  return a;
}

}  // namespace liver_sim
