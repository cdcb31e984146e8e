// The instruments as an OR's tracking system drives them: named, declared and changed by
// instrument_command, each posed from its own topic (instruments/<name>/pose) or tf frame, each
// with its own wrench. Callbacks validate and stage; the simulation thread applies the staged
// changes to the model and publishes. The scene's own instruments are addressable the same way.
#pragma once

#include <geometry_msgs/PoseStamped.h>
#include <ros/ros.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_broadcaster.h>
#include <visualization_msgs/MarkerArray.h>

#include <functional>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "liver_sim/InstrumentCommand.h"
#include "liver_sim/SimulationStatus.h"
#include "liver_sim/simulation/liver_model.h"

namespace liver_sim {

class RosInstruments {
 public:
  struct Settings {
    std::string frame_id;            // the model frame
    InstrumentOptions tool;          // the default instrument `tool`, out of the scene until posed
    std::vector<std::string> frames; // tf frames, each an instrument of the tool's shape named after it
    double tf_timeout = 0.1;         // s: how long a pose waits for its transform
    double pose_timeout = 1.0;       // s: a pose older than this is stale (0: never)
    bool hold_stale = false;         // a stale instrument stays where it was (else it is withdrawn)
  };

  // Subscribes instrument_command and the pose topics of the tool, the frames' instruments and
  // the model's own. `reject` reports a refused input, `warn` an event (a stale instrument); they
  // may be called under this class's lock and must not call back into it.
  // Throws std::invalid_argument for invalid settings.
  RosInstruments(ros::NodeHandle& nh, ros::NodeHandle& pnh, tf2_ros::Buffer& tf, LiverModel& model,
                 const Settings& settings, std::function<void(const std::string&)> reject,
                 std::function<void(const std::string&)> warn);

  // Simulation thread. Moves staged declarations, poses and tf frames into the model, withdraws
  // (or holds) stale instruments; true when the model's instruments changed.
  bool apply(LiverModel& model);
  // The stamp of the newest pose the last apply() moved into the model (zero: none).
  ros::Time reflected_stamp() const { return reflected_stamp_; }
  // Every instrument out of the scene until its next pose (a reset).
  void release_all(LiverModel& model);
  // Each instrument's wrench (its frame, at its tip), the total (model frame, about its origin),
  // the tip frames of topic-driven instruments, and the instrument markers when they changed.
  void publish(const LiverModel& model, const std_msgs::Header& header);
  void fill_status(const LiverModel& model, SimulationStatus& status) const;
  // Staleness, changed live (dynamic_reconfigure).
  void set_staleness(double pose_timeout, bool hold_stale);

 private:
  struct Tracked {
    int index = -1;                 // in the model; -1 until the simulation thread adds it
    InstrumentOptions shape;        // as declared (pose fields unused)
    bool shape_changed = true;
    std::string frame;              // tf frame driving it, or empty
    ros::Subscriber pose_sub;
    ros::Publisher wrench_pub;
    std::optional<Eigen::Isometry3d> pose;  // the latest pose (model frame); none: not posed by ROS
    bool pose_changed = false;
    ros::Time stamp;                // of the latest pose
    ros::Time received;             // ROS time the latest pose came (zero: a static tf frame)
    ros::Time tf_stamp;             // of the frame's latest transform
    bool stale = false;
    bool removed = false;
    Eigen::Isometry3d drawn = Eigen::Isometry3d::Identity();  // the model's pose last published
  };

  void on_command(const InstrumentCommand::ConstPtr& msg);
  void on_pose(const std::string& name, const geometry_msgs::PoseStamped::ConstPtr& msg);
  // A declaration or change merged into `shape`: "" or the refusal naming the field.
  std::string merge(const InstrumentCommand& c, InstrumentOptions& shape) const;
  // Creates the ROS side of an instrument (mutex held).
  Tracked& track(const std::string& name, const InstrumentOptions& shape, const std::string& frame);
  // The model's instrument for `shape`: the one of its name, or of its name and type when it
  // once had another type (the model keeps an instrument's type for life).
  static int model_slot(LiverModel& model, const InstrumentOptions& shape);
  // A model instrument no tracked one uses and out of the scene at the last step, for a new one
  // when the model is full; kFreeNextFrame when the unused ones were still in the scene at the
  // last step (free once a step has run without them); -1 when there is none (mutex held).
  static constexpr int kFreeNextFrame = -2;
  int free_slot(const LiverModel& model) const;
  void lookup_frame(const std::string& name, Tracked& t);  // mutex held
  std::string frame_of(const std::string& name, const Tracked& t) const;
  void set_pose(Tracked& t, const Eigen::Isometry3d& pose, const ros::Time& stamp, const ros::Time& received);
  visualization_msgs::MarkerArray markers(const LiverModel& model, const std_msgs::Header& header) const;

  ros::NodeHandle nh_, pnh_;
  tf2_ros::Buffer& tf_;
  tf2_ros::TransformBroadcaster tip_broadcaster_;
  Settings settings_;
  std::function<void(const std::string&)> reject_, warn_;
  ros::Subscriber command_sub_;
  ros::Publisher wrench_pub_, marker_pub_;

  mutable std::mutex mutex_;  // guards tracked_, settings_ and the staged changes
  std::map<std::string, Tracked> tracked_;
  std::vector<int> retired_;  // model instruments to take out of the scene (removed or retyped)
  bool markers_due_ = true;   // simulation thread
  ros::Time reflected_stamp_;  // simulation thread
};

}  // namespace liver_sim
