#include "scene_overrides.h"

#include <sstream>
#include <stdexcept>

#include "liver_sim/scene/scene.h"

namespace liver_sim {
namespace {

[[noreturn]] void fail(const std::string& origin, const std::string& text, const std::string& message) {
  throw SceneError(origin + ": --set " + text + ": " + message);
}

// Sets the scalar at `path` (dotted; numbers index sequences), creating missing map keys.
void apply_override(YAML::Node node, const std::vector<std::string>& path, size_t i, const std::string& value,
                    const std::string& origin, const std::string& text) {
  const std::string& key = path[i];
  const bool last = i + 1 == path.size();
  if (node.IsSequence()) {
    size_t index = 0;
    try {
      size_t used = 0;
      index = std::stoul(key, &used);
      if (used != key.size()) throw std::invalid_argument(key);
    } catch (const std::exception&) {
      fail(origin, text, "'" + key + "' is not a list index");
    }
    if (index >= node.size()) fail(origin, text, "index " + key + " out of range");
    YAML::Node child = node[index];
    if (!last) return apply_override(child, path, i + 1, value, origin, text);
    if (child.IsMap() || child.IsSequence()) fail(origin, text, "only scalars can be overridden");
    node[index] = value;
    return;
  }
  if (!node.IsMap() && !node.IsNull()) fail(origin, text, "the path runs through a scalar");
  const YAML::Node existing = static_cast<const YAML::Node&>(node)[key];
  if (last) {
    if (existing && (existing.IsMap() || existing.IsSequence()))
      fail(origin, text, "only scalars can be overridden");
    node[key] = value;
    return;
  }
  if (!existing || existing.IsNull()) node[key] = YAML::Node(YAML::NodeType::Map);
  apply_override(node[key], path, i + 1, value, origin, text);
}

}  // namespace

void apply_overrides(YAML::Node& root, const std::vector<std::string>& overrides, const std::string& origin) {
  for (const std::string& text : overrides) {
    const size_t eq = text.find('=');
    if (eq == std::string::npos || eq == 0) fail(origin, text, "expected dotted.key=value");
    std::vector<std::string> path;
    std::stringstream keys(text.substr(0, eq));
    for (std::string part; std::getline(keys, part, '.');) {
      if (part.empty()) fail(origin, text, "empty key component");
      path.push_back(part);
    }
    apply_override(root, path, 0, text.substr(eq + 1), origin, text);
  }
}

}  // namespace liver_sim
