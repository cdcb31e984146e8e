// Shared by the linear algebra tests: a small box's stiffness assembled sparse and dense.
#pragma once

#include <Eigen/Dense>

#include <vector>

#include "liver_sim/linalg/sparse_pattern.h"
#include "liver_sim/model/corotational_tetra.h"
#include "liver_sim/geometry/mesh.h"

namespace liver_sim {

// Global stiffness of a small box assembled twice: through the pattern and scatter maps, and
// densely by plain index arithmetic.
struct Assembled {
  TetMesh mesh;
  SparsePattern pattern;
  std::vector<double> values;
  Eigen::MatrixXd dense;

  explicit Assembled(int divisions = 2)
      : mesh(make_box_mesh({0.01, 0.01, 0.01}, Eigen::Vector3i::Constant(divisions))),
        pattern(static_cast<int>(mesh.V.rows()), mesh.T) {
    CorotationalTetra tets(mesh.V, mesh.T, ParenchymaOptions{});
    const int n = pattern.rows();
    values.assign(pattern.nonzeros(), 0.0);
    dense.setZero(n, n);
    std::vector<int> map;
    for (int e = 0; e < mesh.T.rows(); ++e) {
      const int nodes[4] = {mesh.T(e, 0), mesh.T(e, 1), mesh.T(e, 2), mesh.T(e, 3)};
      map.clear();
      pattern.append_scatter_map(nodes, 4, map);
      scatter_add(tets.rest_stiffness(e), map.data(), values);
      for (int a = 0; a < 4; ++a)
        for (int b = 0; b < 4; ++b)
          dense.block<3, 3>(3 * nodes[a], 3 * nodes[b]) += tets.rest_stiffness(e).block<3, 3>(3 * a, 3 * b);
    }
    // Clamp the bottom face so that the matrix is positive definite.
    for (int i = 0; i < mesh.V.rows(); ++i) {
      if (mesh.V(i, 2) > 1e-12) continue;
      for (int c = 0; c < 3; ++c) {
        const int d = 3 * i + c;
        dense.row(d).setZero();
        dense.col(d).setZero();
        dense(d, d) = 1;
        for (int k = 0; k < pattern.rows(); ++k) {
          const int idx = pattern.find(std::min(k, d), std::max(k, d));
          if (idx >= 0) values[idx] = (k == d) ? 1.0 : 0.0;
        }
      }
    }
  }
};

}  // namespace liver_sim
