// A remeshed surface coarsened as far as a distance to the surface it approximates allows. The
// remeshing (surface_remesh.h) keeps every edge within a deviation with graded, near-equilateral
// triangles, which spends triangles where the shape does not need them; the volume mesh inside
// holds about two tetrahedra per boundary triangle however coarse its inside, so those triangles
// set the element count. Lengths in metres.
#pragma once

#include <string>

#include "liver_sim/geometry/surface_mesh.h"
#include "liver_sim/meshing/surface_remesh.h"

namespace liver_sim {

struct CoarsenOptions {
  double tolerance = 1e-3;  // m, > 0: every new triangle stays within this of the reference
  double max_edge = 0.02;   // m, > 0: no edge made longer (nor longer than 12 tolerances)
  double min_angle = 25;    // degrees, (0, 60): no collapse makes a triangle thinner than this
};

// `surface`: closed, manifold, outward-oriented, its vertices near `reference` (remesh_surface's
// output). Edge collapses ordered and placed by quadric error metrics (Garland & Heckbert 1997),
// the merged vertex moved along its triangles' normal until they enclose the volume the old ones
// did (Lindstrom & Turk 1998: chords on both sides of a curved part, not all inside), each
// checked on its new triangles: sampled on a grid of sub-triangles the tolerance across, within
// the tolerance of the reference and facing its way; none turned by over 30 degrees. Returns the
// coarsened surface, closed and manifold; the report gives its triangles and smallest angle.
// Throws MeshError naming `origin` for options out of bounds.
SurfaceMesh coarsen_surface(const SurfaceMesh& surface, const SurfaceMesh& reference, const CoarsenOptions& options,
                            const std::string& origin, RemeshReport* report = nullptr);

}  // namespace liver_sim
