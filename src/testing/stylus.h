// A tracked stylus swabbed over the organ's anterior surface, as the intra-operative data of the
// Image-to-Physical Liver Registration Sparse Data Challenge (Heiselman et al., J Med Imaging
// 11(1) 015001, 2024) were recorded: a few strokes across the surface the surgeon sees, points
// every millimetre or two along them, 20-44% of the surface near a stroke. For the benchmarks and
// tests (not the product); built into liver_sim_testing.
//
// The strokes lie where the surgeon reaches: the surface seen from `anterior` (the first surface
// along rays from a plane far out on that side, one ray per `raster` step). Each stroke is that
// surface cut by a plane containing the anterior direction, along a random heading; its points
// are the surface points within half a raster step of the plane, over a random stretch of it
// (strokes do not always cross the whole organ), thinned to `spacing` along it, each moved by the
// tracking's noise. Strokes are added, each at a random offset across the organ, until the
// coverage reaches `coverage`.
//
// Coverage is by area, not by triangles touched (a line crossing 50 triangles covers a strip,
// not their area): the share of the whole surface's area within `reach` of a stroke's point,
// counted on samples spread uniformly over the surface, `reach` / 4 apart on average.
#pragma once

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <Eigen/Core>

namespace liver_sim {

struct StylusSweep {
  Eigen::Vector3d anterior = -Eigen::Vector3d::UnitY();  // toward the surgeon (LPS: -y is anterior)
  double coverage = 0.3;      // -, in (0, 1]: the share of the surface the strokes cover (reached or exceeded)
  double reach = 0.01;        // m, > 0: a surface point within this of a stroke's point is covered
  double spacing = 1.5e-3;    // m, > 0: between a stroke's points
  double noise = 1e-3;        // m, >= 0: the tracking's error, standard deviation per coordinate
  double raster = 1e-3;       // m, > 0: the surface's sampling across the anterior plane
  int max_strokes = 200;      // strokes tried before giving up on the coverage
  unsigned seed = 1;
};

struct StylusData {
  pcl::PointCloud<pcl::PointXYZ> cloud;
  double coverage = 0;        // achieved (below the request only when max_strokes were not enough)
  int strokes = 0;
};

// Strokes over the surface (boundary triangles at positions x, outward normals).
StylusData swab_surface(const Eigen::VectorXd& x, const Eigen::MatrixX3i& boundary, const StylusSweep& sweep);

// The share of the surface's area (triangles at x) within `reach` of a point of `cloud`.
double area_coverage(const Eigen::VectorXd& x, const Eigen::MatrixX3i& boundary, const pcl::PointCloud<pcl::PointXYZ>& cloud,
                     double reach, unsigned seed = 1);

}  // namespace liver_sim
