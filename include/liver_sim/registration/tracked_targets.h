// The points the registration shows the surgeon: the tumour probes and the vessel bifurcations,
// ROS-free.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "liver_sim/simulation/liver_model.h"

namespace liver_sim {

// A point of interest that moves with the tissue.
struct TrackedTarget {
  enum class Kind { Probe, Bifurcation };
  std::string name;
  Kind kind;
  Eigen::Vector3d position;  // m, at the current state
};
// The scene's probes (the tumour) and the vessel nodes where three or more beams meet
// (bifurcations, named "<vessel> bifurcation <node>"), at the model's current state.
std::vector<TrackedTarget> tracked_targets(const LiverModel& model);

}  // namespace liver_sim
