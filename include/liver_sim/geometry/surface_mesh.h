// Closed triangle surfaces, as segmentation tools write them (io/surface_io.h reads and writes
// them; meshing/surface_repair.h checks and repairs them).
#pragma once

#include <Eigen/Core>

#include "liver_sim/geometry/mesh.h"

namespace liver_sim {

// V: #V x 3 vertex positions (file units times the reader's scale). F: #F x 3 vertex indices
// (0-based) of each triangle, in the file's order; readers check the indices only.
struct SurfaceMesh {
  Eigen::MatrixX3d V;
  Eigen::MatrixX3i F;
};

}  // namespace liver_sim
