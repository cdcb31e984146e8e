#include "liver_sim/geometry/surface_locator.h"

#include <algorithm>
#include <array>
#include <cmath>

#include "liver_sim/geometry/closest_points.h"
#include "liver_sim/geometry/node_positions.h"

namespace liver_sim {
namespace {

constexpr int kLeafTriangles = 4;

// The squared distance from p to a box (0 inside), without the per-axis branches of Eigen's
// AlignedBox::squaredExteriorDistance (two per axis and box).
double squared_distance(const Eigen::Vector3d& p, const Eigen::AlignedBox3d& box) {
  const Eigen::Vector3d outside = (box.min() - p).cwiseMax(0.0) + (p - box.max()).cwiseMax(0.0);
  return outside.squaredNorm();
}

}  // namespace

void SurfaceLocator::build(const Eigen::VectorXd& x, const Eigen::MatrixX3i& boundary,
                           const std::optional<Eigen::Vector3d>& viewpoint) {
  triangles_.clear();
  corners_.clear();
  boxes_.clear();
  slot_of_row_.assign(boundary.rows(), -1);
  std::vector<Eigen::Vector3d> centroids;
  for (int t = 0; t < boundary.rows(); ++t) {
    Eigen::Matrix3d v;
    for (int j = 0; j < 3; ++j) v.col(j) = node(x, boundary(t, j));
    const Eigen::Vector3d centroid = v.rowwise().mean();
    if (viewpoint && (v.col(1) - v.col(0)).cross(v.col(2) - v.col(0)).dot(*viewpoint - centroid) <= 0) continue;
    slot_of_row_[t] = static_cast<int>(triangles_.size());
    triangles_.push_back(t);
    corners_.push_back(v);
    centroids.push_back(centroid);
  }
  order_.resize(triangles_.size());
  for (size_t k = 0; k < order_.size(); ++k) order_[k] = static_cast<int>(k);
  if (!triangles_.empty()) build_range(0, static_cast<int>(order_.size()), centroids);
}

// Splits order_[first, first + count) at the median of the centroids along their widest axis.
int SurfaceLocator::build_range(int first, int count, std::vector<Eigen::Vector3d>& centroids) {
  const int index = static_cast<int>(boxes_.size());
  boxes_.emplace_back();
  if (count <= kLeafTriangles) {
    boxes_[index].first = first;
    boxes_[index].count = count;
  } else {
    Eigen::AlignedBox3d spread;
    for (int k = first; k < first + count; ++k) spread.extend(centroids[order_[k]]);
    Eigen::Index axis;
    spread.sizes().maxCoeff(&axis);
    const auto begin = order_.begin() + first, middle = begin + count / 2;
    std::nth_element(begin, middle, begin + count,
                     [&](int a, int b) { return centroids[a][axis] < centroids[b][axis]; });
    build_range(first, count / 2, centroids);
    const int right = build_range(first + count / 2, count - count / 2, centroids);
    boxes_[index].right = right;
  }
  fit(index);
  return index;
}

// A box's bounds from its triangles (a leaf) or its children (fitted before it).
void SurfaceLocator::fit(int b) {
  Box& box = boxes_[b];
  box.bounds.setEmpty();
  if (box.count > 0) {
    for (int k = box.first; k < box.first + box.count; ++k)
      for (int j = 0; j < 3; ++j) box.bounds.extend(corners_[order_[k]].col(j));
  } else {
    box.bounds = boxes_[b + 1].bounds.merged(boxes_[box.right].bounds);
  }
}

void SurfaceLocator::build(const SurfaceMesh& surface) {
  const Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> node_major = surface.V;
  build(Eigen::Map<const Eigen::VectorXd>(node_major.data(), node_major.size()), surface.F);
}

void SurfaceLocator::refresh(const Eigen::VectorXd& x, const Eigen::MatrixX3i& boundary) {
  for (size_t k = 0; k < triangles_.size(); ++k)
    for (int j = 0; j < 3; ++j) corners_[k].col(j) = node(x, boundary(triangles_[k], j));
  for (int b = static_cast<int>(boxes_.size()) - 1; b >= 0; --b) fit(b);  // children first
}

SurfaceLocator::Hit SurfaceLocator::closest(const Eigen::Vector3d& p, double cutoff, int hint) const {
  Hit best;
  if (boxes_.empty()) return best;
  double bound = cutoff * cutoff;  // squared: nothing farther is looked at
  double beyond = std::numeric_limits<double>::infinity();  // squared: the nearest of what was not
  int found = -1;
  Eigen::Vector3d weights;
  auto test = [&](int slot) {
    const Eigen::Matrix3d& v = corners_[slot];
    const Eigen::Vector3d w = closest_on_triangle(p, v.col(0), v.col(1), v.col(2));
    const double d2 = (p - v * w).squaredNorm();
    if (d2 < bound || (found < 0 && d2 <= bound)) {
      bound = d2;
      found = slot;
      weights = w;
    } else {
      beyond = std::min(beyond, d2);
    }
  };
  if (hint >= 0 && hint < static_cast<int>(slot_of_row_.size()) && slot_of_row_[hint] >= 0) test(slot_of_row_[hint]);
  // Depth first, into the nearer child at once, the farther one stacked with its distance (a
  // median-split tree is at most log2(triangles) deep): each box's distance is computed once.
  struct Stacked {
    int box;
    double distance2;
  };
  std::array<Stacked, 64> stack;
  int top = 0;
  int current = 0;
  double current_distance2 = squared_distance(p, boxes_[0].bounds);
  while (true) {
    const Box& box = boxes_[current];
    if (current_distance2 > bound) {
      beyond = std::min(beyond, current_distance2);
    } else if (box.count > 0) {
      for (int k = box.first; k < box.first + box.count; ++k) test(order_[k]);
    } else {
      const int left = current + 1;
      const double to_left = squared_distance(p, boxes_[left].bounds);
      const double to_right = squared_distance(p, boxes_[box.right].bounds);
      const bool left_first = to_left <= to_right;
      stack[top++] = left_first ? Stacked{box.right, to_right} : Stacked{left, to_left};
      current = left_first ? left : box.right;
      current_distance2 = left_first ? to_left : to_right;
      continue;
    }
    if (top == 0) break;
    --top;
    current = stack[top].box;
    current_distance2 = stack[top].distance2;
  }
  if (found < 0) {
    best.distance = std::sqrt(beyond);  // every triangle is at least this far
    return best;
  }
  const Eigen::Matrix3d& v = corners_[found];
  best.triangle = triangles_[found];
  best.weights = weights;
  best.point = v * weights;
  best.distance = (p - best.point).norm();
  best.normal = (v.col(1) - v.col(0)).cross(v.col(2) - v.col(0)).normalized();
  return best;
}

}  // namespace liver_sim
