// The boundary of a mesh cut into patches a few centimetres across, ROS-free: where the
// registration's analyses gather the springs' pull (a patch's net force: the sensor's noise
// cancels in it, a model error does not) and spread the forces the model was not told of.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "liver_sim/model/mechanical_model.h"

namespace liver_sim {

struct SurfacePatches {
  // Centres (rest shape, m): boundary nodes taken in order, none closer than the spacing to an
  // earlier one.
  std::vector<Eigen::Vector3d> centres;
  // Per patch, a unit force spread over the free boundary nodes near its centre: weights by
  // node area times a Gaussian of width spacing / 2, cut at three widths, summing to 1 (a patch
  // whose nodes are all supported has none).
  std::vector<std::vector<int>> nodes;
  std::vector<std::vector<double>> weights;
  std::vector<int> triangle_patch;  // per boundary triangle: the patch whose centre is nearest its centroid
};
SurfacePatches make_surface_patches(MechanicalModel& mechanics, double spacing);

// The net force (N) each patch's springs exert on the surface at positions x.
std::vector<Eigen::Vector3d> patch_spring_forces(const SurfacePatches& patches, const Eigen::MatrixX3i& boundary,
                                                 const std::vector<SurfaceTarget>& springs, const Eigen::VectorXd& x);

}  // namespace liver_sim
