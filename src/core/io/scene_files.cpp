#include "liver_sim/io/scene_files.h"

#include <stdexcept>

#include "liver_sim/io/mesh_io.h"
#include "liver_sim/io/vessel_io.h"

namespace liver_sim {

TetMesh load_scene_mesh(const Scene& scene) {
  if (scene.mesh.file.empty()) return make_box_mesh(scene.mesh.box_size, scene.mesh.box_divisions);
  return read_mesh(scene.mesh.file, scene.mesh.scale);
}

std::vector<VesselTree> load_vessel_trees(const Scene& scene) {
  std::vector<VesselTree> trees(scene.vessels.size());
  for (size_t k = 0; k < trees.size(); ++k) {
    const VesselOptions& v = scene.vessels[k];
    const std::string error = validate(v);
    if (!error.empty()) throw std::invalid_argument(error);
    if (!v.enabled) continue;
    try {
      trees[k] = read_vessel_tree(v.file, v.scale);
    } catch (const VesselError& e) {
      throw std::invalid_argument("vessels." + v.name + ": " + e.what());
    }
  }
  return trees;
}

}  // namespace liver_sim
