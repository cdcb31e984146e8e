// A smooth surface from a binary volume (VTK from Debian): the inside indicator is blurred with a
// Gaussian and its 0.5 level set is contoured (flying edges), its facets smoothed (windowed sinc)
// and the triangles decimated (quadric edge collapse).
// A level set of a continuous field never crosses itself and is closed, so the result has none
// of a segmentation surface's self-crossings or holes, and the blur removes stair-steps and noise
// finer than its width.
#pragma once

#include <string>

#include "liver_sim/geometry/surface_mesh.h"
#include "liver_sim/meshing/voxel_mask.h"

namespace liver_sim {

struct IsosurfaceOptions {
  double smoothing = 1e-3;     // m, > 0: standard deviation of the Gaussian blur
  int max_triangles = 40000;   // decimated down to about this many (gmsh's classification time
                               // grows with the count); <= 0: not decimated
};

// The boundary of `mask` (which must leave a border of empty voxels at least 3 standard
// deviations wide), outward-oriented, metres, LPS. Throws MeshError naming `origin` when the
// contour is empty.
SurfaceMesh isosurface(const VoxelMask& mask, const IsosurfaceOptions& options, const std::string& origin);

}  // namespace liver_sim
