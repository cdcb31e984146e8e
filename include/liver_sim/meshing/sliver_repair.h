// Slivers a Delaunay mesher leaves behind (flat tetrahedra: four nearly coplanar nodes) removed
// or opened up, so that the smallest dihedral angle reaches a target. gmsh's optimiser moves
// interior nodes but cannot touch a sliver whose four nodes lie on the boundary.
#pragma once

#include <limits>

#include "liver_sim/geometry/mesh.h"

namespace liver_sim {

struct SliverRepairReport {
  int peeled = 0;       // boundary slivers removed
  int moved_nodes = 0;  // nodes moved
  double before_deg = 0, after_deg = 0;  // smallest dihedral angle before and after
};

// Up to eight rounds of: (1) peeling boundary slivers under the target (four nodes on the
// boundary, two or three faces on it; the surface moves by the sliver's thickness, and a peel
// that would make an edge or node non-manifold is skipped); (2) moving each node of the
// remaining ones (a boundary node in the boundary's tangent plane, a quarter of its longest
// edge at most) to where the smallest dihedral angle of its tetrahedra is largest (a pattern
// search; every tetrahedron stays positive). Nodes no tetrahedron uses
// any more are dropped. The result may still miss the target: the caller checks it.
// `max_boundary_move` (m): how far the boundary may leave the one the mesher made: a peel only
// where the surface it removes lies within this of the faces it lays bare (the ridge from the
// inner edge, the cap's apex from its inner face) and those faces within this of the original
// boundary around the sliver (sampled); a boundary node may slide along its original triangles
// but stay within this of them. The caller measures what the boundary's triangles then deviate.
SliverRepairReport repair_slivers(TetMesh& mesh, double min_dihedral_deg,
                                  double max_boundary_move = std::numeric_limits<double>::infinity());

// Smallest dihedral angle of one tetrahedron in degrees; -1 when its volume is not positive.
double min_dihedral_deg(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                        const Eigen::Vector3d& d);

}  // namespace liver_sim
