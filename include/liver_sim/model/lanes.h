// One value of each of four elements, and one 3x3 matrix of each: the element kernels run on
// four elements at once, vectorized across them (each element's own arithmetic is a chain of
// dependent operations that leaves the vector units idle).
#pragma once

#include <Eigen/Core>

namespace liver_sim {

using Lanes = Eigen::Array4d;

struct LaneMatrix {
  Lanes m[3][3];
  Lanes& operator()(int i, int j) { return m[i][j]; }
  const Lanes& operator()(int i, int j) const { return m[i][j]; }
};

}  // namespace liver_sim
