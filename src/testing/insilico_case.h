// The Open-CAS in-silico liver registration case (../shared/data/opencas-insilico, NOTICE.md
// there): a patient's liver (3D-IRCADb-01) deformed by another group's simulation; the initial
// and deformed volumes share their nodes, so every interior node is a target with a known true
// position, and partial views of the deformed surface stand for the intra-operative data.
// Licence CC BY-NC-ND 3.0: read where it lies, never copied into the repository, nothing derived
// from it committed. For the benchmarks and tests (not the product); built into liver_sim_testing.
#pragma once

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <Eigen/Core>
#include <optional>
#include <string>
#include <vector>

#include "liver_sim/geometry/mesh.h"
#include "liver_sim/geometry/surface_mesh.h"

namespace liver_sim {

struct InsilicoCase {
  TetMesh initial;                  // m (the files are in mm)
  Eigen::MatrixX3d deformed;        // m: where each node of `initial` went
  std::vector<int> targets;         // the interior nodes (on no boundary triangle)
  std::vector<double> depth;        // m, per target: its distance to the initial surface
  std::vector<std::string> view_names;  // partial views of the deformed surface
  std::vector<SurfaceMesh> views;       // m
};

// The data folder's path: the LIVER_SIM_INSILICO environment variable, else `fallback`.
std::string insilico_folder(const std::string& fallback);
// Reads the case from `folder`: initial-volume.vtk, deformed-volume.vtk (mm) and the partial
// views, every other .stl than initial-surface.stl and deformed-surface.stl (by name). Cases
// of the same form: scripts/make_neohookean_truth.py. Nullopt with the reason in `why` when a
// file is absent (the data are not distributed with the product). Throws MeshError for a file
// that does not read.
std::optional<InsilicoCase> load_insilico_case(const std::string& folder, std::string* why);

// Points sampled uniformly over a surface's area, `spacing` apart on average (m), with Gaussian
// noise of `noise` (m, standard deviation per coordinate): a dense sensor's view of it.
pcl::PointCloud<pcl::PointXYZ> sample_surface(const SurfaceMesh& surface, double spacing, double noise, unsigned seed);

// Target registration errors (m) over all targets and over the deepest tenth of them.
struct TreSummary {
  double mean = 0, p95 = 0, max = 0;  // all targets
  double deep_mean = 0, deep_p95 = 0, deep_max = 0;  // the deepest 10%
  double deep_from = 0;  // m: the depth where the deepest 10% start
};
TreSummary summarise_tre(const std::vector<double>& errors, const std::vector<double>& depth);

// How well squared Mahalanobis distances d^2 = e^T C^-1 e of errors e under their covariances C
// follow the chi-square distribution with 3 degrees of freedom (that of a calibrated 3-D
// Gaussian): the share inside the 95% ellipsoids (d^2 <= 7.81), the median (2.37 when
// calibrated) and the Kolmogorov-Smirnov distance to it.
struct Calibration {
  int count = 0;
  double inside_95 = 0, median = 0, ks = 0;
};
Calibration calibration(std::vector<double> d2);
double chi_square3_cdf(double x);

}  // namespace liver_sim
