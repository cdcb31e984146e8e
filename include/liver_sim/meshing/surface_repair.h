// Checks a segmented surface before it is meshed, repairs what can be repaired without
// changing the shape, and refuses the rest with the defect named and located.
#pragma once

#include <string>
#include <vector>

#include "liver_sim/geometry/surface_mesh.h"

namespace liver_sim {

struct SurfaceRepairOptions {
  // Vertices closer than this are one vertex (the surface's length unit); <= 0: 1e-6 times the
  // bounding-box diagonal (STL stores every corner separately, in float32: 1e-7 relative).
  double merge_distance = 0.0;
  // Several disconnected shells: keep the one enclosing the largest volume instead of refusing.
  bool keep_largest_shell = false;
};

// What was repaired, with one line per repair for the user.
struct SurfaceRepairs {
  int merged_vertices = 0;       // vertices merged into an earlier one within merge_distance
  int unused_vertices = 0;       // vertices used by no triangle, dropped
  int collapsed_triangles = 0;   // triangles with two corners on one vertex, dropped
  int duplicate_triangles = 0;   // triangles on the same three vertices as an earlier one, dropped
  int reoriented_triangles = 0;  // triangles turned to agree with their neighbours and face outward
  bool inside_out = false;       // every triangle faced inward: the whole surface was turned
  int dropped_shells = 0;        // shells other than the largest (keep_largest_shell)
  std::vector<std::string> notes;
};

// A defect of the surface's topology or geometry (a hole, a non-manifold edge or vertex, a
// non-orientable or self-crossing surface, several shells) that a new surface from the enclosed
// volume can mend (resurface.h), unlike an unreadable or absurd input.
class SurfaceDefectError : public MeshError {
 public:
  using MeshError::MeshError;
};

// Merges duplicate vertices, drops collapsed and duplicate triangles and unused vertices,
// orients every triangle consistently with the normals pointing out of the enclosed volume.
// Throws MeshError naming `origin`, the defect and where it is (indices of the input's triangles
// and vertices, coordinates) for: no triangles, a non-finite coordinate, an index out of range,
// coordinates too large to handle in double precision; SurfaceDefectError for an open boundary (an edge of one triangle
// only), a non-manifold edge (three or more triangles) or vertex (two sheets touching at a point),
// a non-orientable shell, several disconnected shells (unless keep_largest_shell), two triangles
// crossing each other (self-intersection) or folded onto each other across their edge.
SurfaceMesh repair_surface(const SurfaceMesh& surface, const std::string& origin,
                           const SurfaceRepairOptions& options = {}, SurfaceRepairs* repairs = nullptr);

// Volume enclosed by a closed, outward-oriented surface (divergence theorem; length unit cubed).
double enclosed_volume(const SurfaceMesh& surface);

}  // namespace liver_sim
