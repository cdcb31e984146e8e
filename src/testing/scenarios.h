// Synthetic intra-operative scenarios for the benchmarks and the tests (not the product): a
// view of the surface, a retractor's lift and the other deformations of surgery. Built into
// liver_sim_testing. A depth sensor's view with its defects: depth_camera.h.
#pragma once

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <Eigen/Core>

#include <string>
#include <vector>

#include "depth_camera.h"
#include "liver_sim/geometry/mesh.h"
#include "liver_sim/scene/options.h"

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
// in its first 40% along x (the phantom's right lobe: the patient's right is -x in LPS).
LoadOptions underside_lift(const TetMesh& mesh, double newtons);
// A camera 25 cm from the centroid of positions x, anterior-superior (-y, +z), looking at it.
CameraView front_view(const Eigen::VectorXd& x);

// An instrument the camera sees: a shaft from a tissue surface node (its tip rests on the
// surface there, pushed out along the node's normal by the radius) to a fixed trocar.
struct VisibleInstrument {
  int node = -1;
  Eigen::Vector3d trocar = Eigen::Vector3d::Zero();  // m
  double radius = 5e-3;                              // m
};
// A deformation of surgery on the phantom's anatomy: the loads that make it at full strength
// (added to the scene's), and the instruments that make it. Regions are placed from the rest
// mesh's bounding box and nearest surface nodes, so that the same name loads the same anatomy on
// any mesh of the phantom (the model's and the finer truth's).
//   lift              a retractor under the right lobe: 5 N up (underside_lift)
//   press             an instrument pressing the right lobe's anterior face above the tumour:
//                     2 N posterior and down, on the nodes within 12 mm of the contact
//   breathing         the diaphragm pushing the superior dome 4 N caudally and anteriorly
//   pneumoperitoneum  the insufflation's pressure on the anterior third, 300 Pa inward
struct SurgicalScenario {
  std::string name;
  std::vector<LoadOptions> loads;
  std::vector<VisibleInstrument> instruments;
};
// Throws std::invalid_argument for an unknown name.
SurgicalScenario surgical_scenario(const std::string& name, const TetMesh& mesh);
const std::vector<std::string>& surgical_scenario_names();
// The loads times s (forces and pressures; gravity is not among them).
std::vector<LoadOptions> scaled(const std::vector<LoadOptions>& loads, double s);
// The scenario's instruments where the tissue (boundary triangles at positions x) has them.
std::vector<InstrumentShaft> instrument_shafts(const SurgicalScenario& scenario, const Eigen::VectorXd& x,
                                               const Eigen::MatrixX3i& boundary);
// The depth camera at front_view's pose, looking at the centroid of x.
DepthCamera front_depth_camera(const Eigen::VectorXd& x);

}  // namespace liver_sim
