// A synthetic depth camera for the registration benchmark and tests (not the product): what a
// structured-light or stereo sensor returns of a deforming liver, with its defects. Built into
// liver_sim_testing.
//
// One ray per pixel of a pinhole camera meets the first surface: a boundary triangle of the
// tissue or an instrument's shaft (a capsule). Then, as real sensors do:
//   - depth noise along the ray growing with the square of the depth (stereo and structured
//     light: sigma_z = b z^2 / (f B) for a disparity error b, focal length f, baseline B), and a
//     smaller lateral jitter of a fraction of a pixel;
//   - no return at grazing angles (all returns up to `grazing_start`, none beyond
//     `grazing_limit`, a falling share between) and next to depth discontinuities (silhouettes,
//     instrument edges), where the correlation window straddles two depths;
//   - instruments occlude the tissue behind them and return points of their own, which are
//     outliers for the registration;
//   - patches of blood: the sensor sees a liquid film above the capsule (points biased toward the
//     camera);
//   - a partial field of view: a cone about the optical axis narrowed until the tissue in sight
//     in it (returned or lost to the defects above) covers `visible_fraction` of the whole
//     boundary area.
#pragma once

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <Eigen/Core>
#include <vector>

namespace liver_sim {

// A rigid instrument as the camera sees it: a shaft (capsule) of `radius` from `tip` to `trocar`.
struct InstrumentShaft {
  Eigen::Vector3d tip = Eigen::Vector3d::Zero();     // m
  Eigen::Vector3d trocar = Eigen::Vector3d::Zero();  // m
  double radius = 5e-3;                              // m
};

struct DepthCamera {
  Eigen::Vector3d eye = Eigen::Vector3d::Zero();     // m: the optical centre
  Eigen::Vector3d target = Eigen::Vector3d::Zero();  // m: a point on the optical axis
  Eigen::Vector3d up = Eigen::Vector3d::UnitZ();     // image "up", not parallel to the axis
  int width = 640, height = 480;                     // pixels, >= 8
  double horizontal_fov = 1.05;                      // rad (60 deg), in (0, pi)
  double visible_fraction = 0.3;   // of the boundary area in view; 1: the whole image
  double depth_noise = 1e-3;       // m: standard deviation along the ray at `reference_depth`
  double reference_depth = 0.25;   // m, > 0: sigma_z = depth_noise (z / reference_depth)^2
  double lateral_noise = 0.3;      // pixels, standard deviation in each image direction
  double grazing_start = 1.13;     // rad (65 deg): returns thin out beyond this incidence
  double grazing_limit = 1.48;     // rad (85 deg): no return beyond this incidence
  double edge_jump = 5e-3;         // m: pixels next to a larger depth step return nothing
  int blood_patches = 2;           // discs of blood on the visible tissue
  double blood_radius = 8e-3;      // m
  double blood_depth = 2e-3;       // m: the film's thickness (points that much nearer the camera)
  unsigned seed = 1;
};

struct DepthCloud {
  pcl::PointCloud<pcl::PointXYZ> cloud;  // model frame (m)
  double visible_fraction = 0;   // tissue area in view / boundary area (below the request when
                                 // the camera sees less)
  double returned_fraction = 0;  // tissue area that returned points / boundary area
  int tissue_points = 0, instrument_points = 0, blood_points = 0;
  int grazing_dropped = 0, edge_dropped = 0;  // tissue pixels in the field of view lost to each
};

// The view of the tissue (boundary triangles `boundary` at positions x, outward normals) and
// the instruments from `camera`.
DepthCloud render_depth_cloud(const Eigen::VectorXd& x, const Eigen::MatrixX3i& boundary,
                              const std::vector<InstrumentShaft>& instruments, const DepthCamera& camera);

// Standard deviation of a point's depth error (m) at distance `depth` along the optical axis.
double depth_sigma(const DepthCamera& camera, double depth);

}  // namespace liver_sim
