// VTK XML unstructured grid (.vtu, ASCII) of a tetrahedral mesh with a point displacement field,
// for ParaView ("Warp By Vector") and the plotting scripts.
#pragma once

#include <Eigen/Core>
#include <string>

#include "liver_sim/geometry/mesh.h"

namespace liver_sim {

// Points are the rest positions (m); `displacement` is 3 #V, node-major (m).
// Throws std::runtime_error when the file cannot be written.
void write_vtu(const std::string& path, const TetMesh& mesh, const Eigen::VectorXd& displacement);

}  // namespace liver_sim
