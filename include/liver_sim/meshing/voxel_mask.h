// The liver as a binary volume on a voxel grid: from a surface as segmentations give it (self-
// crossings, small holes, stair-steps; rebuilt by voting rays) or from a label map (one label
// taken). isosurface.h turns it into a smooth surface. Lengths in metres, positions in LPS.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "liver_sim/geometry/surface_mesh.h"
#include "liver_sim/io/label_map_io.h"

namespace liver_sim {

// Voxel (i, j, k), i fastest, is inside or not; its centre lies at origin + axes * (i, j, k).
// The grid may be oblique and anisotropic (a label map's direction times its spacing).
struct VoxelMask {
  Eigen::Array3i dims = Eigen::Array3i::Zero();
  Eigen::Matrix3d axes = Eigen::Matrix3d::Identity();  // columns: one step of i, j, k (m, LPS)
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();    // centre of voxel (0, 0, 0) (m, LPS)
  std::vector<std::uint8_t> inside;                    // 1 inside, 0 outside
  std::size_t index(long i, long j, long k) const {
    return static_cast<std::size_t>(i + static_cast<long>(dims[0]) * (j + static_cast<long>(dims[1]) * k));
  }
  Eigen::Vector3d centre(double i, double j, double k) const { return origin + axes * Eigen::Vector3d(i, j, k); }
  double voxel_volume() const { return std::abs(axes.determinant()); }
};

struct VoxelizeReport {
  long long inside_voxels = 0;
  long long disputed_voxels = 0;  // the three ray directions did not all agree (holes, flips)
};

// Inside or outside of each voxel centre of an axis-aligned grid of step `voxel` around the
// surface (with `padding` empty voxels on every side), by the winding number counted along rays
// in x, y and z through it, a majority of the three deciding. Signed crossings (the triangles'
// orientation, taken so that the enclosed volume is positive) make a region the surface wraps
// twice, where it crosses itself, inside; a ray through a small hole misses a crossing and
// is outvoted by the two other directions. The surface need not be closed, manifold or free of
// crossings; its triangles need not share vertices. Throws MeshError naming `origin` when the
// surface encloses no voxel, or when so many voxels are disputed (over a tenth of those inside)
// that the surface does not bound a volume, with where the disputed voxels lie.
VoxelMask voxelize_surface(const SurfaceMesh& surface, double voxel, int padding, const std::string& origin,
                           VoxelizeReport* report = nullptr);

// The voxels of `label` in a label map, cropped to their bounding box plus `padding` voxels.
// Throws MeshError naming `origin` when no voxel has the label (with the labels present).
VoxelMask label_mask(const LabelImage& image, int label, int padding, const std::string& origin);

struct ComponentReport {
  int components = 0;            // 6-connected pieces inside
  long long dropped_voxels = 0;  // in the pieces dropped
  long long filled_voxels = 0;   // cavities (outside voxels the outside cannot reach) filled
};

// Keeps one 6-connected piece and fills its cavities. Pieces under `speck` times the largest's
// voxels are segmentation noise, dropped; larger ones are refused (MeshError naming `origin`, the
// pieces' volumes and where they are) unless keep_largest.
void keep_one_piece(VoxelMask& mask, bool keep_largest, double speck, const std::string& origin,
                    ComponentReport* report = nullptr);

}  // namespace liver_sim
