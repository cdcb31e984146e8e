#include "liver_sim/meshing/surface_deviation.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <vector>

#include "liver_sim/geometry/surface_locator.h"

namespace liver_sim {
namespace {

// Sub-triangles per edge at most: a million samples on a triangle.
constexpr double kMaxDivisions = 1000;

OneSidedDeviation one_sided(const SurfaceMesh& from, const SurfaceMesh& to, double spacing) {
  if (to.F.rows() == 0) throw std::invalid_argument("surface_deviation: a surface without triangles");
  SurfaceLocator locator;
  locator.build(to);
  OneSidedDeviation d;
  auto sample = [&](const Eigen::Vector3d& p) {
    const double r = locator.closest(p).distance;
    if (r > d.max) {
      d.max = r;
      d.farthest = p;
    }
    return r;
  };
  // Vertices of the triangles only: a tetrahedral mesh's boundary shares V with interior nodes.
  std::vector<char> used(from.V.rows(), 0);
  for (Eigen::Index t = 0; t < from.F.rows(); ++t)
    for (int k = 0; k < 3; ++k) used[from.F(t, k)] = 1;
  for (Eigen::Index i = 0; i < from.V.rows(); ++i)
    if (used[i]) sample(from.V.row(i).transpose());
  double weighted = 0, area_sum = 0;
  for (Eigen::Index t = 0; t < from.F.rows(); ++t) {
    const Eigen::Vector3d a = from.V.row(from.F(t, 0)), b = from.V.row(from.F(t, 1)), c = from.V.row(from.F(t, 2));
    const double area = 0.5 * (b - a).cross(c - a).norm();
    const double longest = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
    const double divisions = std::ceil(longest / spacing);
    if (!(divisions <= kMaxDivisions))  // NaN included: a non-finite vertex
      throw std::invalid_argument("surface_deviation: a spacing of " + std::to_string(spacing) +
                                  " samples a triangle with more than 1000 sub-triangles along an edge");
    const int k = std::max(1, static_cast<int>(divisions));
    double sum = 0;
    // Centroids of the sub-triangles pointing like the triangle ((i + 1/3)/k, (j + 1/3)/k), then
    // of those pointing the other way ((i + 2/3)/k, (j + 2/3)/k).
    for (int i = 0; i < k; ++i)
      for (int j = 0; i + j < k; ++j) {
        sum += sample(a + (i + 1.0 / 3) / k * (b - a) + (j + 1.0 / 3) / k * (c - a));
        if (i + j < k - 1) sum += sample(a + (i + 2.0 / 3) / k * (b - a) + (j + 2.0 / 3) / k * (c - a));
      }
    weighted += area * sum / (static_cast<double>(k) * k);
    area_sum += area;
  }
  d.mean = area_sum > 0 ? weighted / area_sum : 0;
  return d;
}

}  // namespace

SurfaceDeviation surface_deviation(const SurfaceMesh& a, const SurfaceMesh& b, double spacing) {
  if (!(spacing > 0) || !std::isfinite(spacing)) throw std::invalid_argument("surface_deviation: the spacing must be finite and > 0");
  return {one_sided(a, b, spacing), one_sided(b, a, spacing)};
}

}  // namespace liver_sim
