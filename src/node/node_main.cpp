// liver_sim_node's main: the options, the simulation thread's processors and scheduling, the
// callbacks' spinner and the heartbeat on the other processors, then the loop on this thread.
#include <ros/package.h>
#include <ros/ros.h>

#include <algorithm>
#include <memory>
#include <thread>

#include "liver_sim/runtime/worker_pool.h"
#include "liver_sim_node.h"
#include "node_options.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "liver_sim");
  // The clouds and the analyses free and allocate the same blocks again, frame after frame.
  if (!liver_sim::keep_freed_memory()) ROS_WARN("liver_sim: the allocator keeps handing freed memory back to the system");
  ros::NodeHandle nh, pnh("~");
  liver_sim::NodeOptions options;
  const std::vector<int> processors = liver_sim::processors_of_calling_thread();
  try {
    // The default scene from where ROS finds the package (its install space's share folder, or
    // its sources beside a devel space), not from where it was built.
    options = liver_sim::read_node_options(pnh, ros::package::getPath("liver_sim") + "/config/scenes/liver_phantom.yaml");
  } catch (const std::exception& e) {
    ROS_FATAL("liver_sim: %s", e.what());
    return 1;
  }
  if (const std::string error = liver_sim::scheduling_error(options, processors); !error.empty()) {
    ROS_FATAL("liver_sim: %s", error.c_str());
    return 1;
  }
  // The processors the simulation leaves (all of them when it leaves none): the callbacks, the
  // services and the background work (factor refreshes, analyses) run there.
  std::vector<int> others;
  for (int cpu : processors)
    if (std::find(options.cpu_affinity.begin(), options.cpu_affinity.end(), cpu) == options.cpu_affinity.end())
      others.push_back(cpu);
  if (others.empty()) others = processors;
  if (!options.cpu_affinity.empty()) options.helper_processors = others;
  // The simulation thread (this one): its processors and its scheduling, set before the model is
  // built so that the model's helper threads inherit them. Refused settings leave it as it was.
  if (!options.cpu_affinity.empty()) {
    const std::string refused = liver_sim::pin_calling_thread(options.cpu_affinity);
    if (!refused.empty()) ROS_WARN("liver_sim: ~cpu_affinity refused (%s); the simulation runs on any processor", refused.c_str());
  }
  if (options.realtime_priority != 0) {
    const std::string refused = liver_sim::set_realtime_priority(options.realtime_priority);
    if (!refused.empty())
      ROS_WARN("liver_sim: ~realtime_priority %d refused (%s); the simulation runs at normal priority",
               options.realtime_priority, refused.c_str());
  }
  std::unique_ptr<liver_sim::LiverSimNode> node;
  try {
    node = std::make_unique<liver_sim::LiverSimNode>(nh, pnh, options);
  } catch (const std::exception& e) {
    ROS_FATAL("liver_sim: %s", e.what());
    return 1;
  }
  // Callbacks and services run beside the simulation loop, at normal priority, on the others:
  // their threads inherit both from the thread that starts them.
  ros::AsyncSpinner spinner(2);
  std::thread([&] {
    liver_sim::set_realtime_priority(0);
    liver_sim::pin_calling_thread(others);
    spinner.start();
    node->start_heartbeat();
  }).join();
  // The threads that wake to pass messages on run at once on a core the simulation keeps busy:
  // without it, on one core shared with 100,000-point clouds, ~status went out up to 93 ms late
  // (doc/robustness.md, node soak).
  if (options.thread_slice > 0) {
    const std::string refused = liver_sim::set_slice_of_other_threads(options.thread_slice);
    if (!refused.empty()) ROS_WARN("liver_sim: ~thread_slice refused (%s); the kernel's slice stays", refused.c_str());
  }
  node->run();
  return 0;
}
