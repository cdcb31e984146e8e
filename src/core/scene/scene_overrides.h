// The scene files' dotted overrides (`--set solver.dt=0.001`, the node's ~solver/* and so on),
// applied to the YAML tree before it is read: private to the scene part.
#pragma once

#include <yaml-cpp/yaml.h>

#include <string>
#include <vector>

namespace liver_sim {

// Each "dotted.key=value" sets the scalar at its path (numbers index sequences), creating missing
// map keys; throws SceneError naming `origin` and the override.
void apply_overrides(YAML::Node& root, const std::vector<std::string>& overrides, const std::string& origin);

}  // namespace liver_sim
