// The named instruments of a tracking session, ROS-free: an OR's tracking system declares,
// changes and removes them by name, and poses each from a stream of its own or from a frame the
// caller looks up at the start of each frame. Names map to the model's instrument slots: the
// model keeps an instrument's type for life, so a retyped instrument takes another slot, and a
// removed one's slot goes to a new instrument once the model is full. The scene's own
// instruments are addressable the same way. Any thread stages a command or a pose (the latest
// per instrument: nothing queues); the simulation thread applies them to the model at the start
// of a frame, withdrawing (or holding) instruments whose poses went stale.
#pragma once

#include <Eigen/Geometry>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "liver_sim/session/inputs.h"
#include "liver_sim/session/notices.h"
#include "liver_sim/simulation/liver_model.h"

namespace liver_sim {

const char* instrument_type_word(InstrumentOptions::Type t);  // "probe", "shaft", "tube", "grasper"
// Why `name` cannot name an instrument ("" when it can): 1 to 32 letters, digits or '_' (the
// node makes topic names of them).
std::string instrument_name_error(const std::string& name);

class InstrumentSlots {
 public:
  struct Settings {
    std::optional<InstrumentOptions> tool;  // the default instrument `tool`, out of the scene until posed
    std::vector<std::string> frames;  // frames, each driving an instrument of the tool's shape named after it
    double pose_timeout = 1.0;        // s: a pose older than this is stale (0: never)
    bool hold_stale = false;          // a stale instrument stays where it was (else it is withdrawn)
  };

  // The scene's instruments of `model`, the tool (unless the scene has one of that name) and one
  // per frame, of the tool's shape.
  // Refusals and events go to `notices`. Throws std::invalid_argument for invalid settings.
  InstrumentSlots(const LiverModel& model, const Settings& settings, Notices& notices);

  // Any thread. A command or a pose, validated and staged (a refusal goes to the notices);
  // `command` returns whether it was accepted.
  bool command(const InstrumentRequest& c);
  void pose(const InstrumentPose& p);
  void frame_pose(const FramePose& p, Stamp now);
  void set_staleness(double pose_timeout, bool hold_stale);

  // Simulation thread. Moves the staged declarations and poses into the model, withdraws (or
  // holds) stale instruments. `now`: the frame's stamp clock. True when the model must step: its
  // instruments changed, or a slot frees once a step has run.
  bool apply(LiverModel& model, Stamp now);
  // Whether apply() or release_all() changed an instrument of the model since the last call.
  bool take_redrawn();
  // The stamp of the newest pose the last apply() moved into the model (0: none).
  Stamp reflected_stamp() const { return reflected_stamp_; }
  // Every posed instrument out of the scene until its next pose (a reset).
  void release_all(LiverModel& model);

  // The declared instruments (by name), with their model slots (-1 until applied) and the frame
  // that drives them (empty: their own stream). Any thread.
  struct Slot {
    std::string name;
    int index = -1;
    std::string frame;
    bool waiting = false;  // driven by a frame that has given no pose yet: out of the scene
  };
  std::vector<Slot> slots() const;

 private:
  struct Tracked {
    int index = -1;                 // in the model; -1 until the simulation thread adds it
    InstrumentOptions shape;        // as declared (pose fields unused)
    bool shape_changed = true;
    std::string frame;              // the frame driving it, or empty
    std::optional<Eigen::Isometry3d> pose;  // the latest pose (model frame); none: not posed
    bool pose_changed = false;
    Stamp stamp = 0;                // of the latest pose
    Stamp received = 0;             // when the latest pose came (0: a static frame, never stale)
    Stamp frame_stamp = 0;          // of the frame's latest transform
    bool stale = false;
    bool removed = false;
  };

  // A declaration or change merged into `shape`: "" or the refusal naming the field.
  std::string merge(const InstrumentRequest& c, InstrumentOptions& shape) const;
  // The model's instrument for `shape`: the one of its name, or of its name and type when it
  // once had another type (the model keeps an instrument's type for life).
  static int model_slot(const LiverModel& model, const InstrumentOptions& shape);
  // A model instrument no tracked one uses and out of the scene at the last step, for a new one
  // when the model is full; kFreeNextFrame when the unused ones were still in the scene at the
  // last step (free once a step has run without them); -1 when there is none (mutex held).
  static constexpr int kFreeNextFrame = -2;
  int free_slot(const LiverModel& model) const;
  void set_pose(Tracked& t, const Eigen::Isometry3d& pose, Stamp stamp, Stamp received);
  void refuse(std::unique_lock<std::mutex>& lock, const std::string& why);

  Settings settings_;
  Notices& notices_;
  mutable std::mutex mutex_;  // guards tracked_, settings_ and the staged changes
  std::map<std::string, Tracked> tracked_;
  std::vector<int> retired_;  // model instruments to take out of the scene (removed or retyped)
  Stamp reflected_stamp_ = 0;  // simulation thread
  bool redrawn_ = true;        // simulation thread
};

}  // namespace liver_sim
