// The files a scene names: its mesh and its vessels' centre lines.
#pragma once

#include <vector>

#include "liver_sim/geometry/mesh.h"
#include "liver_sim/geometry/vessel_tree.h"
#include "liver_sim/scene/scene.h"

namespace liver_sim {

// Builds the mesh a scene asks for (box or file). Throws MeshError / SceneError.
TetMesh load_scene_mesh(const Scene& scene);

// The centre lines of scene.vessels, one per entry in order (empty for a disabled vessel).
// Throws std::invalid_argument naming the vessel ("vessels.NAME: ...") for an invalid option or a
// file that does not load.
std::vector<VesselTree> load_vessel_trees(const Scene& scene);

}  // namespace liver_sim
