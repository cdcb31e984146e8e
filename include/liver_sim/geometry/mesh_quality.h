// Shape quality of tetrahedral meshes, as mesh generators report it.
#pragma once

#include "liver_sim/geometry/mesh.h"

namespace liver_sim {

struct TetQuality {
  double min_dihedral_deg = 0;   // smallest dihedral angle of any tetrahedron (degrees; 70.53 regular)
  double max_dihedral_deg = 0;   // largest (degrees)
  double min_radius_ratio = 0;   // 3 r_in / r_circ: 1 for the regular tetrahedron, 0 degenerate
  double mean_radius_ratio = 0;
  int worst_dihedral = -1;       // tetrahedron of the smallest dihedral angle
  int worst_radius_ratio = -1;   // tetrahedron of the smallest radius ratio
};

// Over every tetrahedron of the mesh (at least one).
TetQuality tet_quality(const TetMesh& mesh);

}  // namespace liver_sim
