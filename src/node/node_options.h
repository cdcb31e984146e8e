// The node's private parameters (~name; README, 'ROS interface'), read once into one struct and
// checked before anything is built: each with its unit and bounds (cfg/LiverSim.cfg for those
// that can change live). liver_sim.launch passes each from an argument of its own.
#pragma once

#include <ros/node_handle.h>
#include <xmlrpcpp/XmlRpcValue.h>

#include <string>
#include <vector>

namespace liver_sim {

struct NodeOptions {
  std::string scene;                  // scene file (YAML)
  std::string frame_id = "liver";     // the model frame
  std::string parent_frame;           // the OR's frame the model frame hangs from (empty: none)
  std::vector<double> parent_transform{0, 0, 0, 0, 0, 0, 1};  // [x, y, z (m), qx, qy, qz, qw]
  double rate = 30;                   // Hz, [1, 1000]: frames a second
  double publish_rate = 30;           // Hz, [0.1, 100]: meshes a second at most
  double step_time_budget = 1.0 / 30; // s, > 0
  bool budget_follows_rate = true;    // neither ~step_time_budget nor ~solver/time_budget: one frame of ~rate
  int test_fault_every = 0;           // >= 0 (test hook)
  // dotted.key=value overrides of the scene: the node's real-time defaults, then ~parenchyma/*,
  // ~capsule/*, ~solver/*, ~contact/*, ~registration/* and ~threads.
  std::vector<std::string> scene_overrides;
  int threads = -1;                   // [1, WorkerPool::kMaxThreads]; -1 (unset): the scene's
  double uncertainty_period = 1.0;    // s, >= 0
  bool one_shot = false;              // the first cloud (and one far from the model) registered in one shot
  double cloud_margin = 0.05;         // m, >= 0
  double instrument_radius = 0.003;   // m: the tool's and the frames' instruments
  double instrument_length = 0.1;     // m
  std::vector<std::string> instrument_frames;
  double instrument_tf_timeout = 0.1; // s, [0, 1]
  double pose_timeout = 1.0;          // s, [0, 60]; 0: never stale
  bool hold_stale_instruments = false;
  double color_scale_max = 0.005;     // m
  double surface_alpha = 1.0;         // [0, 1]
  std::vector<int> cpu_affinity;      // processors of the simulation thread; empty: any
  int realtime_priority = 0;          // [0, 99]; 0: normal
  double thread_slice = 1e-4;         // s, 0 or [1e-4, 0.1]
  // Not a parameter: with ~cpu_affinity, the processors it leaves, where the background work
  // runs (SessionOptions::helper_processors); empty: beside the simulation.
  std::vector<int> helper_processors;
};

// Reads every parameter; throws std::invalid_argument naming the first one out of its bounds.
NodeOptions read_node_options(const ros::NodeHandle& pnh, const std::string& default_scene);

// The checks, each "" when valid, else the refusal naming the parameter.
std::string rates_error(double rate, double publish_rate);
// The display and staleness values the node keeps itself, against cfg/LiverSim.cfg's bounds.
std::string view_error(double color_scale_max, double surface_alpha, double pose_timeout);
std::string options_error(const NodeOptions& o);  // all but the scheduling
// The scheduling, against the processors this process may use.
std::string scheduling_error(const NodeOptions& o, const std::vector<int>& processors);
// A scalar parameter as a scene override's value; throws std::invalid_argument for a non-scalar.
std::string scalar_text(const XmlRpc::XmlRpcValue& v);

}  // namespace liver_sim
