// A mesh's node positions as one vector, as the models and solvers hold them: node i's x, y, z
// at entries 3i, 3i + 1, 3i + 2 (m).
#pragma once

#include <Eigen/Core>

namespace liver_sim {

// Node i's position in the stacked positions x.
inline Eigen::Vector3d node(const Eigen::VectorXd& x, int i) { return x.segment<3>(3 * i); }

}  // namespace liver_sim
