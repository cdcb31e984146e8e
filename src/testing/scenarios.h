// Synthetic intra-operative scenarios for the benchmarks and the tests (not the product): a
// depth camera's view of the surface and a retractor's lift. Built into liver_sim_testing.
#pragma once

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <Eigen/Core>

#include "liver_sim/mesh.h"
#include "liver_sim/options.h"

namespace liver_sim {

// A synthetic intra-operative view, for benchmarks and tests: points sampled uniformly on the
// boundary triangles at positions x, kept where the camera at `eye` sees them (front-facing,
// not hidden: a depth buffer), then the `visible_fraction` of the whole surface area nearest to
// the view axis (eye -> target), Gaussian noise of `noise` (m, per coordinate), and a share of
// outliers spread uniformly over the box of the view's points grown by 2 cm.
struct CameraView {
  Eigen::Vector3d eye = Eigen::Vector3d::Zero();     // m
  Eigen::Vector3d target = Eigen::Vector3d::Zero();  // m
  double visible_fraction = 0.3;  // of the boundary area
  double noise = 0.0;             // m
  double outlier_fraction = 0.0;  // of the returned points
  double spacing = 2e-3;          // m: mean distance between samples on the surface
  unsigned seed = 1;
};
struct SyntheticCloud {
  pcl::PointCloud<pcl::PointXYZ> cloud;
  double visible_fraction = 0;  // achieved (below the request when the camera sees less)
  int outliers = 0;
};
SyntheticCloud render_surface_cloud(const Eigen::VectorXd& x, const Eigen::MatrixX3i& boundary, const CameraView& view);

// The synthetic scenario of register_bench and the tests. A retractor lifting the liver:
// `newtons` upward (+z), spread over the nodes of the mesh's underside (the lowest quarter in z)
// in its last 40% along x (the phantom's right lobe).
LoadOptions underside_lift(const TetMesh& mesh, double newtons);
// A camera 25 cm from the centroid of positions x, anterior-superior (-y, +z), looking at it.
CameraView front_view(const Eigen::VectorXd& x);

}  // namespace liver_sim
