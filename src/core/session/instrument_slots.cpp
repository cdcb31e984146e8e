#include "liver_sim/session/instrument_slots.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "liver_sim/contact/instrument.h"

namespace liver_sim {
namespace {

std::optional<InstrumentOptions::Type> parse_type(const std::string& s) {
  for (auto t : {InstrumentOptions::Type::Probe, InstrumentOptions::Type::Shaft, InstrumentOptions::Type::Tube,
                 InstrumentOptions::Type::Grasper})
    if (s == instrument_type_word(t)) return t;
  return std::nullopt;
}

// A frame's or a scene instrument's name as an instrument name.
std::string slot_name(const std::string& name) {
  std::string s = name;
  for (char& c : s)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_')) c = '_';
  return s;
}

}  // namespace

const char* instrument_type_word(InstrumentOptions::Type t) {
  switch (t) {
    case InstrumentOptions::Type::Probe: return "probe";
    case InstrumentOptions::Type::Shaft: return "shaft";
    case InstrumentOptions::Type::Tube: return "tube";
    case InstrumentOptions::Type::Grasper: return "grasper";
  }
  return "";
}

std::string instrument_name_error(const std::string& name) {
  if (name.empty() || name.size() > 32) return "name must have 1 to 32 characters";
  for (char c : name)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_'))
      return "name '" + name + "' may hold letters, digits and '_' only";
  return "";
}

InstrumentSlots::InstrumentSlots(const LiverModel& model, const Settings& settings, Notices& notices)
    : settings_(settings), notices_(notices) {
  if (!(settings_.pose_timeout >= 0)) throw std::invalid_argument("pose_timeout must be >= 0 s");
  if (settings_.tool) {
    settings_.tool->name = "tool";
    settings_.tool->enabled = false;
    const std::string tool_error = validate(*settings_.tool);
    if (!tool_error.empty()) throw std::invalid_argument("the tool's shape: " + tool_error);
  } else if (!settings_.frames.empty()) {
    throw std::invalid_argument("instrument frames need the tool's shape");
  }
  // The scene's instruments keep their names in the model; the session knows them by names
  // that may only hold letters, digits and '_'.
  for (int i = 0; i < model.num_instruments(); ++i) {
    const std::string name = slot_name(model.instrument(i).name).substr(0, 32);
    if (tracked_.count(name)) throw std::invalid_argument("scene instruments '" + name + "': two names give one instrument name");
    Tracked& t = tracked_[name];
    t.shape = model.instrument(i);
    t.index = i;
    t.shape_changed = false;
  }
  std::vector<std::pair<std::string, std::string>> declared;
  if (settings_.tool && !tracked_.count("tool")) declared.emplace_back("tool", "");  // a scene's own `tool` takes the name
  for (const std::string& frame : settings_.frames) declared.emplace_back(slot_name(frame), frame);
  for (const auto& [name, frame] : declared) {
    const std::string error = instrument_name_error(name);
    if (!error.empty()) throw std::invalid_argument("instrument frames: " + error);
    if (tracked_.count(name)) throw std::invalid_argument("instrument frames: the instrument name '" + name + "' is taken");
    Tracked& t = tracked_[name];
    t.shape = *settings_.tool;
    t.shape.name = name;
    t.frame = frame;
  }
  if (static_cast<int>(tracked_.size()) > kMaxInstruments)
    throw std::invalid_argument("more than " + std::to_string(kMaxInstruments) + " instruments");
}

void InstrumentSlots::refuse(std::unique_lock<std::mutex>& lock, const std::string& why) {
  lock.unlock();
  notices_.refuse(why);
}

std::string InstrumentSlots::merge(const InstrumentRequest& c, InstrumentOptions& shape) const {
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

bool InstrumentSlots::command(const InstrumentRequest& c) {
  std::string error = instrument_name_error(c.name);
  if (!error.empty()) {
    notices_.refuse("instrument_command: " + error);
    return false;
  }
  std::unique_lock<std::mutex> lock(mutex_);
  const auto it = tracked_.find(c.name);
  const bool exists = it != tracked_.end() && !it->second.removed;
  if (c.remove) {
    if (!exists) {
      refuse(lock, "instrument_command: no instrument '" + c.name + "' to remove");
      return false;
    }
    it->second.removed = true;
    return true;
  }
  if (!exists && c.type.empty()) error = "no instrument '" + c.name + "' to change; a type declares one";
  int count = 0;
  for (const auto& [name, t] : tracked_) count += !t.removed;
  if (!exists && count >= kMaxInstruments) error = "at most " + std::to_string(kMaxInstruments) + " instruments";
  InstrumentOptions shape = exists ? it->second.shape : InstrumentOptions{};
  if (!exists) shape.name = c.name;  // an existing one keeps its name in the model
  if (error.empty()) error = merge(c, shape);
  if (!error.empty()) {
    refuse(lock, error.rfind("instrument_command", 0) == 0 ? error : "instrument_command " + c.name + ": " + error);
    return false;
  }
  if (!exists) {
    if (it != tracked_.end()) {  // removed, not yet applied: declared anew
      if (it->second.index >= 0) retired_.push_back(it->second.index);
      tracked_.erase(it);
    }
    Tracked& t = tracked_[c.name];
    t.shape = shape;
    t.frame = c.frame;
    return true;
  }
  Tracked& t = it->second;
  t.shape = shape;
  t.shape_changed = true;
  // A declaration sets the pose source (empty frame: its own stream); a change keeps it unless named.
  const std::string frame = c.type.empty() && c.frame.empty() ? t.frame : c.frame;
  if (frame != t.frame) {
    t.frame = frame;
    t.pose.reset();  // until the new source's first pose
    t.pose_changed = true;
  }
  return true;
}

void InstrumentSlots::pose(const InstrumentPose& p) {
  const std::string topic = "instruments/" + p.name + "/pose";
  std::unique_lock<std::mutex> lock(mutex_);
  const auto it = tracked_.find(p.name);
  if (it == tracked_.end() || it->second.removed) return;
  if (!it->second.frame.empty()) return refuse(lock, topic + ": the instrument follows tf frame '" + it->second.frame + "'");
  // Refused on arrival, as the model would refuse it (a later pose may replace it before a frame).
  InstrumentOptions posed = it->second.shape;
  posed.position = p.position;
  posed.orientation = p.orientation;
  const std::string error = validate(posed);
  if (!error.empty()) return refuse(lock, topic + ": " + error);
  set_pose(it->second, make_pose(posed.position, posed.orientation), p.stamp, p.received);
}

void InstrumentSlots::frame_pose(const FramePose& p, Stamp now) {
  if (!p.pose.matrix().allFinite()) return notices_.refuse("instrument " + p.name + ": non-finite transform of " + p.frame);
  std::lock_guard<std::mutex> lock(mutex_);
  const auto it = tracked_.find(p.name);
  if (it == tracked_.end() || it->second.removed || it->second.frame != p.frame) return;
  Tracked& t = it->second;
  // A static frame (stamp zero) never goes stale; a moving one ages from when its transform
  // last advanced, on this computer's clock (the tracker's may differ).
  if (p.stamp == 0) {
    set_pose(t, p.pose, 0, 0);
  } else if (!t.pose || p.stamp != t.frame_stamp) {
    t.frame_stamp = p.stamp;
    set_pose(t, p.pose, p.stamp, now);
  }
}

void InstrumentSlots::set_pose(Tracked& t, const Eigen::Isometry3d& pose, Stamp stamp, Stamp received) {
  // A re-sent pose changes nothing, so costs no step.
  if (!t.pose || t.pose->matrix() != pose.matrix() || t.stale) {
    t.pose = pose;
    t.pose_changed = true;
    t.stamp = stamp;
  }
  t.stale = false;
  t.received = received;
}

int InstrumentSlots::free_slot(const LiverModel& model) const {
  bool freed_now = false;
  for (int i = 0; i < model.num_instruments(); ++i) {
    if (std::any_of(tracked_.begin(), tracked_.end(), [i](const auto& named) { return named.second.index == i; }))
      continue;
    if (model.instrument_withdrawn(i)) return i;
    freed_now = true;
  }
  return freed_now ? kFreeNextFrame : -1;
}

int InstrumentSlots::model_slot(const LiverModel& model, const InstrumentOptions& shape) {
  const int own = model.find_instrument(shape.name);
  if (own >= 0 && model.instrument(own).type == shape.type) return own;
  return model.find_instrument(shape.name + "." + instrument_type_word(shape.type));
}

bool InstrumentSlots::apply(LiverModel& model, Stamp now) {
  std::unique_lock<std::mutex> lock(mutex_);
  std::vector<std::pair<Notices::Kind, std::string>> told;  // after the lock, in order
  bool changed = false;
  reflected_stamp_ = 0;
  for (auto it = tracked_.begin(); it != tracked_.end();) {
    const std::string& name = it->first;
    Tracked& t = it->second;
    if (t.removed) {
      if (t.index >= 0) retired_.push_back(t.index);
      it = tracked_.erase(it);
      continue;
    }
    if (t.pose && !t.stale && settings_.pose_timeout > 0 && t.received != 0 &&
        static_cast<double>(now - t.received) * kSecondsPerStamp > settings_.pose_timeout) {
      t.stale = true;
      if (!settings_.hold_stale) {
        t.pose_changed = true;
        std::ostringstream why;
        why << "instrument " << name << ": no pose for " << settings_.pose_timeout << " s; withdrawn until the next";
        told.emplace_back(Notices::Kind::Event, why.str());
      }
    }
    if (t.index >= 0 && !t.shape_changed && !t.pose_changed) {
      ++it;
      continue;
    }
    InstrumentOptions o = t.shape;
    if (t.pose) {  // the caller drives it: the pose replaces any trajectory of the scene
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
        if (model.find_instrument(o.name) >= 0) o.name += std::string(".") + instrument_type_word(o.type);
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
      redrawn_ = true;
    } catch (const std::invalid_argument& e) {
      told.emplace_back(Notices::Kind::Refusal, "instrument " + name + ": " + e.what());
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
    redrawn_ = true;
  }
  retired_.clear();
  lock.unlock();
  for (const auto& [kind, text] : told) kind == Notices::Kind::Refusal ? notices_.refuse(text) : notices_.tell(text);
  return changed;
}

bool InstrumentSlots::take_redrawn() {
  const bool redrawn = redrawn_;
  redrawn_ = false;
  return redrawn;
}

void InstrumentSlots::release_all(LiverModel& model) {
  std::lock_guard<std::mutex> lock(mutex_);
  for (auto& [name, t] : tracked_) {
    if (!t.pose || t.index < 0) continue;
    t.pose.reset();
    t.stale = false;
    InstrumentOptions o = model.instrument(t.index);
    o.enabled = false;
    model.update_instrument(t.index, o);
    redrawn_ = true;
  }
}

void InstrumentSlots::set_staleness(double pose_timeout, bool hold_stale) {
  std::lock_guard<std::mutex> lock(mutex_);
  settings_.pose_timeout = pose_timeout;
  if (settings_.hold_stale != hold_stale)
    for (auto& [name, t] : tracked_) t.pose_changed |= t.stale;  // held ones withdrawn, or back
  settings_.hold_stale = hold_stale;
}

std::vector<InstrumentSlots::Slot> InstrumentSlots::slots() const {
  std::lock_guard<std::mutex> lock(mutex_);
  std::vector<Slot> v;
  for (const auto& [name, t] : tracked_)
    if (!t.removed) v.push_back({name, t.index, t.frame, !t.frame.empty() && !t.pose});
  return v;
}

}  // namespace liver_sim
