// The instruments of InstrumentContact (instrument_contact.h): the set, and what a step does to
// them before and after its Newton iterations (poses, stages, holds, suction, reactions).
#include "liver_sim/contact/instrument_contact.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "liver_sim/contact/instrument_shape.h"
#include "surface_samples.h"

namespace liver_sim {
namespace {

constexpr int kMaxStages = 16;  // instrument stages per step
constexpr int kMaxRetreats = 32;  // steps back along the axis of an instrument that appears

void require_valid(const std::string& message) {
  if (!message.empty()) throw std::invalid_argument(message);
}

const ContactOptions& validated(const ContactOptions& o) {
  require_valid(validate(o));
  return o;
}

}  // namespace

InstrumentContact::InstrumentContact(MechanicalModel& mechanics, const ContactOptions& options)
    : mechanics_(mechanics), options_(validated(options)), problem_(mechanics) {
  x_stage_ = mechanics_.rest_positions();
}

int InstrumentContact::add_instrument(const InstrumentOptions& o, double time) {
  require_valid(validate(o));
  if (find_instrument(o.name) >= 0) throw std::invalid_argument("instruments." + o.name + ": the name is taken");
  if (num_instruments() >= kMaxInstruments)
    throw std::invalid_argument("instruments." + o.name + ": at most " + std::to_string(kMaxInstruments) +
                                " instruments in a model");
  InstrumentSlot in;  // placed, then listed: a failure (memory) leaves the list as it was
  place(in, o, time);
  instruments_.push_back(std::move(in));
  return num_instruments() - 1;
}

void InstrumentContact::replace_instrument(int i, const InstrumentOptions& o, double time) {
  require_valid(validate(o));
  const int named = find_instrument(o.name);
  if (named >= 0 && named != i) throw std::invalid_argument("instruments." + o.name + ": the name is taken");
  InstrumentSlot& in = instruments_.at(i);
  // Out of the scene at the last step: the detection kept no contact of it.
  if (!withdrawn(i)) throw std::invalid_argument("instruments." + in.options.name + ": in the scene, not replaced");
  const int suction_load = in.suction_load;  // a former tube's load stays with the slot (its pressure 0 from the next step)
  in = InstrumentSlot();
  in.suction_load = suction_load;
  place(in, o, time);
}

void InstrumentContact::place(InstrumentSlot& in, const InstrumentOptions& o, double time) {
  in.options = o;
  in.pose = in.pose_start = pose_at(o, time);
  if (shape_of(o.type).sucks() && in.suction_load < 0) in.suction_load = mechanics_.add_pressure_load();
}

void InstrumentContact::update_instrument(int i, const InstrumentOptions& o) {
  require_valid(validate(o));
  InstrumentSlot& in = instruments_.at(i);
  if (o.type != in.options.type || o.name != in.options.name)
    throw std::invalid_argument("instruments." + in.options.name + ": name and type cannot change");
  in.options = o;
}

std::string InstrumentContact::set_options(const ContactOptions& o) {
  const std::string error = validate(o);
  if (error.empty()) options_ = o;
  return error;
}

int InstrumentContact::find_instrument(const std::string& name) const {
  for (int i = 0; i < num_instruments(); ++i)
    if (instruments_[i].options.name == name) return i;
  return -1;
}

void InstrumentContact::reset() {
  contacts_.clear();
  for (InstrumentSlot& in : instruments_) {
    in.closed = false;
    in.was_enabled = false;
    in.held.clear();
    in.held_local.clear();
    in.reaction = InstrumentReaction{};
  }
}

void InstrumentContact::save(State& s) const {
  s.instruments = instruments_;
  s.contacts = contacts_;
  s.suction.clear();
  for (const InstrumentSlot& in : instruments_)
    if (in.suction_load >= 0) s.suction.push_back(mechanics_.pressure_load(in.suction_load));
  s.x_stage = x_stage_;
  s.stage_from = stage_from_;
  s.stage_to = stage_to_;
}

void InstrumentContact::restore(const State& s) {
  instruments_ = s.instruments;
  contacts_ = s.contacts;
  size_t k = 0;
  for (const InstrumentSlot& in : instruments_)
    if (in.suction_load >= 0) mechanics_.pressure_load(in.suction_load) = s.suction[k++];
  x_stage_ = s.x_stage;
  stage_from_ = s.stage_from;
  stage_to_ = s.stage_to;
}

int InstrumentContact::begin_step(double t, const Eigen::VectorXd& x) {
  int stages = 1;
  for (InstrumentSlot& in : instruments_) {
    const InstrumentOptions& o = in.options;
    const InstrumentShape& shape = shape_of(o.type);
    in.pose_start = in.pose;
    in.pose = pose_at(o, t);
    if (o.enabled && shape.pushes()) {
      if (!in.was_enabled) in.pose_start = entry_pose(in, x);
      // In floating point until capped: the travel may be any finite length (the cast of a
      // value beyond int's range is undefined).
      const double travel = shape.travel(o, in.pose_start, in.pose);
      stages = std::max(stages, static_cast<int>(std::min<double>(kMaxStages, std::ceil(travel / (0.25 * shape.size(o))))));
    }
    in.was_enabled = o.enabled;
    shape.hold(in, t, x, mechanics_);
    // A slot that held a tube keeps its load (with no pressure unless it holds a tube again).
    if (in.suction_load >= 0) shape.suction(o, in.pose, mechanics_.boundary(), x, mechanics_.pressure_load(in.suction_load));
  }
  stage_from_.clear();
  stage_to_.clear();
  for (const InstrumentSlot& in : instruments_) {
    stage_from_.push_back(in.pose_start);
    stage_to_.push_back(in.pose);
  }
  return stages;
}

Eigen::Isometry3d InstrumentContact::entry_pose(const InstrumentSlot& in, const Eigen::VectorXd& x) const {
  // It comes in along its axis from where it touches the surface nowhere. Each retreat by the
  // deepest penetration brings that closer (for a rod through the surface, by its radius at a
  // time until its tip is out).
  const InstrumentShape& shape = shape_of(in.options.type);
  Eigen::Isometry3d entry = in.pose;
  for (int retreat = 0; retreat < kMaxRetreats; ++retreat) {
    double depth = 0;
    near_triangles(mechanics_.boundary(), in.options, entry, x, 0.0,
                   [&](int, const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
                     depth = std::max(depth, -shape.deepest_point(in.options, entry, a, b, c).distance.distance);
                   });
    if (depth <= 0) break;
    entry.translation() += depth * in.pose.linear().col(2);
  }
  return entry;
}

void InstrumentContact::begin_stage(int k, int stages, const Eigen::VectorXd& x) {
  for (int i = 0; i < num_instruments(); ++i) {
    InstrumentSlot& in = instruments_[i];
    in.pose_start = k == 1 ? stage_from_[i] : in.pose;
    const double s = static_cast<double>(k) / stages;
    in.pose = make_pose((1 - s) * stage_from_[i].translation() + s * stage_to_[i].translation(),
                        Eigen::Quaterniond(stage_from_[i].linear()).slerp(s, Eigen::Quaterniond(stage_to_[i].linear())));
  }
  x_stage_ = x;
}

void InstrumentContact::end_step(const Eigen::VectorXd& x) {
  for (InstrumentSlot& in : instruments_) in.reaction = InstrumentReaction{};
  for (const Contact& c : contacts_) {
    if (c.lambda.isZero(0.0)) continue;
    InstrumentReaction& reaction = instruments_[c.instrument].reaction;
    const Eigen::Vector3d force = c.frame * c.lambda;
    reaction.force -= force;
    reaction.torque -= (c.point.at(x) - instruments_[c.instrument].pose.translation()).cross(force);
    ++reaction.contacts;
  }
}

}  // namespace liver_sim
