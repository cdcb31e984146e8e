// Distance between two triangle surfaces (how much shape a remeshing lost): sampled points of
// each against the exact closest point on the other's triangles.
#pragma once

#include <Eigen/Core>

#include "liver_sim/geometry/surface_mesh.h"

namespace liver_sim {

struct OneSidedDeviation {
  double max = 0;   // largest distance of a sample of the first surface to the second
  double mean = 0;  // area-weighted mean over the first surface
  Eigen::Vector3d farthest = Eigen::Vector3d::Zero();  // the sample where the largest was found
};

// Both directions; the Hausdorff distance is the larger of the two maxima. Samples: every vertex
// of a triangle (V may hold other points: a tetrahedral mesh's interior nodes),
// and on each triangle the centroids of its k x k sub-triangles, k = ceil(longest edge / spacing)
// (each standing for 1/k^2 of the triangle's area, so the means are area-weighted). Distances are
// exact point-to-triangle distances (SurfaceLocator). Same length unit as the surfaces. Throws
// std::invalid_argument unless spacing is finite and > 0, for a surface without triangles, and
// for k above 1000 (a spacing too fine for the triangles: up to a million samples each).
struct SurfaceDeviation {
  OneSidedDeviation a_to_b, b_to_a;
  double hausdorff() const { return std::max(a_to_b.max, b_to_a.max); }
};
SurfaceDeviation surface_deviation(const SurfaceMesh& a, const SurfaceMesh& b, double spacing);

}  // namespace liver_sim
