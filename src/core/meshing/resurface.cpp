#include "liver_sim/meshing/resurface.h"

#include <cmath>
#include <sstream>

#include "liver_sim/meshing/isosurface.h"
#include "liver_sim/meshing/surface_repair.h"

namespace liver_sim {
namespace {

// Pieces under this share of the largest one's voxels are segmentation specks, dropped.
constexpr double kSpeck = 0.01;

SurfaceMesh contour(VoxelMask& mask, const ResurfaceOptions& options, const std::string& origin, ResurfaceReport& r) {
  ComponentReport pieces;
  keep_one_piece(mask, options.keep_largest, kSpeck, origin, &pieces);
  r.pieces = pieces.components;
  r.dropped_voxels = pieces.dropped_voxels;
  r.filled_voxels = pieces.filled_voxels;
  std::ostringstream note;
  note << "re-surfaced on a grid of " << mask.dims[0] << " x " << mask.dims[1] << " x " << mask.dims[2] << " voxels of "
       << r.voxel_size * 1e3 << " mm, smoothing " << options.smoothing * 1e3 << " mm";
  r.notes.push_back(note.str());
  if (pieces.components > 1)
    r.notes.push_back("kept the largest of " + std::to_string(pieces.components) + " pieces; dropped " +
                      std::to_string(pieces.dropped_voxels) + " voxels");
  if (pieces.filled_voxels > 0) r.notes.push_back("filled cavities of " + std::to_string(pieces.filled_voxels) + " voxels");
  IsosurfaceOptions iso;
  iso.smoothing = options.smoothing;
  iso.max_triangles = options.max_triangles;
  // The contour is closed and free of crossings by construction; the check holds it to that
  // and drops a speck the blur may have cut off. The decimation can fold it where the surface
  // comes close to itself: then the contour is taken whole.
  SurfaceRepairOptions check;
  check.keep_largest_shell = true;
  SurfaceMesh s;
  try {
    s = repair_surface(isosurface(mask, iso, origin), origin + " (re-surfaced)", check);
  } catch (const SurfaceDefectError& e) {
    if (iso.max_triangles <= 0) throw;
    r.notes.push_back(std::string("the decimated contour failed its check (") + e.what() + "): kept whole");
    iso.max_triangles = 0;
    s = repair_surface(isosurface(mask, iso, origin), origin + " (re-surfaced)", check);
  }
  r.triangles = static_cast<int>(s.F.rows());
  return s;
}

int padding(double smoothing, const Eigen::Matrix3d& axes) {
  // Three standard deviations of the blur, and one voxel more, of empty voxels around.
  const double step = std::min({axes.col(0).norm(), axes.col(1).norm(), axes.col(2).norm()});
  return 2 + static_cast<int>(std::ceil(3 * smoothing / step));
}

}  // namespace

SurfaceMesh resurface(const SurfaceMesh& surface, const ResurfaceOptions& options, const std::string& origin,
                      ResurfaceReport* report) {
  ResurfaceReport r;
  r.voxel_size = options.voxel_size;
  VoxelizeReport votes;
  VoxelMask mask = voxelize_surface(surface, options.voxel_size,
                                    padding(options.smoothing, options.voxel_size * Eigen::Matrix3d::Identity()), origin,
                                    &votes);
  r.inside_voxels = votes.inside_voxels;
  r.disputed_voxels = votes.disputed_voxels;
  if (votes.disputed_voxels > 0)
    r.notes.push_back("rays in x, y and z disagreed on " + std::to_string(votes.disputed_voxels) + " of " +
                      std::to_string(votes.inside_voxels) + " voxels inside (holes or crossings): the majority kept");
  SurfaceMesh s = contour(mask, options, origin, r);
  if (report) *report = r;
  return s;
}

SurfaceMesh resurface(const LabelImage& image, int label, const ResurfaceOptions& options, const std::string& origin,
                      ResurfaceReport* report) {
  ResurfaceReport r;
  r.voxel_size = std::min({image.axes.col(0).norm(), image.axes.col(1).norm(), image.axes.col(2).norm()});
  VoxelMask mask = label_mask(image, label, padding(options.smoothing, image.axes), origin);
  for (const std::uint8_t v : mask.inside) r.inside_voxels += v;
  SurfaceMesh s = contour(mask, options, origin, r);
  if (report) *report = r;
  return s;
}

}  // namespace liver_sim
