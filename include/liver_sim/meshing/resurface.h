// A new surface for a segmentation the mesher cannot take as it is: the volume the input
// encloses is rebuilt on a voxel grid (voxel_mask.h: rays voting over a surface, or one label of
// a label map), kept as one piece without cavities, and contoured smooth (isosurface.h). The
// result passes repair_surface's checks (closed, manifold, no self-crossing); how far it lies
// from the input is the caller's to measure (surface_deviation.h).
#pragma once

#include <string>
#include <vector>

#include "liver_sim/geometry/surface_mesh.h"
#include "liver_sim/io/label_map_io.h"
#include "liver_sim/meshing/voxel_mask.h"

namespace liver_sim {

struct ResurfaceOptions {
  double voxel_size = 1e-3;   // m, > 0: grid step for a surface (a label map keeps its own grid)
  double smoothing = 1e-3;    // m, > 0: Gaussian width; stair-steps and noise finer than this go
  int max_triangles = 40000;  // the contour is decimated to about this many triangles
  bool keep_largest = false;  // several pieces: keep the largest instead of refusing
};

struct ResurfaceReport {
  double voxel_size = 0;           // m (a label map: its smallest step)
  long long inside_voxels = 0;
  long long disputed_voxels = 0;   // rays disagreed (holes, flipped triangles); a surface only
  int pieces = 0;                  // 6-connected pieces inside (one kept)
  long long dropped_voxels = 0;    // in the pieces dropped (specks, or all but the largest)
  long long filled_voxels = 0;     // cavities filled
  int triangles = 0;               // of the new surface
  std::vector<std::string> notes;  // one line each for the user
};

SurfaceMesh resurface(const SurfaceMesh& surface, const ResurfaceOptions& options, const std::string& origin,
                      ResurfaceReport* report = nullptr);
SurfaceMesh resurface(const LabelImage& image, int label, const ResurfaceOptions& options, const std::string& origin,
                      ResurfaceReport* report = nullptr);

}  // namespace liver_sim
