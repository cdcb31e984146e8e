// A closed smooth surface re-meshed with well-shaped triangles whose edge length follows a size
// field. A re-surfaced segmentation (resurface.h) has as many and as irregular triangles as its
// voxels and the decimation made; the volume mesher wants few, near-equilateral ones, small only
// where the surface curves or thins. Isotropic remeshing (Botsch & Kobbelt 2004; the size field
// as in Dunyach et al. 2013): edges longer than 4/3 of the size are split, shorter than 4/5 of it
// collapsed, edges flipped toward six triangles per vertex, vertices moved in the tangent plane
// toward their neighbours' centre; every vertex is projected back onto the reference surface.
// No crease is kept: a level set has none. Lengths in metres.
#pragma once

#include <string>
#include <vector>

#include "liver_sim/geometry/surface_mesh.h"

namespace liver_sim {

struct RemeshOptions {
  // m, > 0: an edge whose middle lies farther than this from the reference is split as well,
  // where the curvature the sizes came from was underestimated (a sharp rim between vertices)...
  double deviation = 0.5e-3;
  double min_size = 1e-3;  // m, > 0: ...unless it is shorter than this
  int iterations = 8;      // rounds of split, collapse, flip and smoothing
  // Vertices the remeshing may make, at most (MeshError past it: splitting that runs away);
  // 0: the reference's vertices plus 16 A / L^2 over its triangles, A the area, L the size
  // there or min_size where that is shorter.
  size_t max_vertices = 0;
};

struct RemeshReport {
  int triangles = 0;
  double min_angle_deg = 0;  // smallest angle of a triangle
};

// `reference`: closed, manifold, outward-oriented (repair_surface's output). `size`: the target
// edge length at each reference vertex (> 0), interpolated linearly across the triangles.
// Returns a closed, manifold, outward-oriented surface whose vertices lie on the reference.
// Throws MeshError naming `origin` when the sizes do not fit the reference or the vertices
// exceed max_vertices.
SurfaceMesh remesh_surface(const SurfaceMesh& reference, const std::vector<double>& size, const RemeshOptions& options,
                           const std::string& origin, RemeshReport* report = nullptr);

// The edge length wanted at each vertex of a smooth closed surface: an edge of length L on a
// surface of curvature k bulges L^2 k / 8 from it, so L = sqrt(8 deviation / k), clamped to
// [min_size, max_size]; k is the largest curvature of the circles touching the surface at the
// vertex through a neighbour (the largest principal curvature on a smooth surface). No longer
// than the radius of the largest ball touching the surface there from inside or outside
// (shrinking balls), so that remeshed sheets across a thin part or a narrow gap do not cross.
// Graded: no vertex's size exceeds a neighbour's by more than `gradation` times the path between
// them (Dijkstra over the edges), so that sizes change gently and the triangles stay well shaped.
std::vector<double> curvature_sizes(const SurfaceMesh& surface, double deviation, double min_size, double max_size,
                                    double gradation);

}  // namespace liver_sim
