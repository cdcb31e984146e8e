// Closest points on a triangulated surface, ROS-free: a bounding-volume hierarchy (axis-aligned
// boxes, median splits) over the triangles, searched branch and bound, exact. The registration
// asks it for every cloud point at every correspondence update; the surface moves between them,
// so the boxes are refitted to the new positions rather than the tree rebuilt.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <limits>
#include <optional>
#include <vector>

#include "liver_sim/geometry/surface_mesh.h"

namespace liver_sim {

class SurfaceLocator {
 public:
  struct Hit {
    int triangle = -1;  // row of the boundary; -1: none within the cutoff
    Eigen::Vector3d weights = Eigen::Vector3d::Zero();  // barycentric of the closest point
    Eigen::Vector3d point = Eigen::Vector3d::Zero();    // m
    Eigen::Vector3d normal = Eigen::Vector3d::Zero();   // the triangle's outward unit normal
    double distance = std::numeric_limits<double>::infinity();  // m; with no triangle, a lower bound
  };
  // The triangles `boundary` (rows: node indices into x, 3 per node) at positions x; with a
  // viewpoint, only those whose front faces it (a camera sees no back face).
  void build(const Eigen::VectorXd& x, const Eigen::MatrixX3i& boundary,
             const std::optional<Eigen::Vector3d>& viewpoint = std::nullopt);
  // A surface's own triangles at its vertices.
  void build(const SurfaceMesh& surface);
  // The same triangles at new positions x: the boxes are refitted, the tree kept (it stays exact;
  // only its pruning weakens as the surface moves far from the shape it was built on).
  void refresh(const Eigen::VectorXd& x, const Eigen::MatrixX3i& boundary);
  // The closest point of the triangles to p, exact. With a cutoff (m), only triangles within it
  // are looked at: a point farther than the cutoff from all of them gets no triangle, and as
  // its distance a lower bound of it (above the cutoff). A `hint` (a boundary row, e.g. the
  // point's last hit) that is near narrows the search from the start. Safe to call from several
  // threads.
  Hit closest(const Eigen::Vector3d& p, double cutoff = std::numeric_limits<double>::infinity(), int hint = -1) const;
  bool empty() const { return triangles_.empty(); }

 private:
  struct Box {
    Eigen::AlignedBox3d bounds;
    int first = 0, count = 0;  // leaf: slots order_[first, first + count); inner: count 0
    int right = 0;             // inner: the right child (the left one follows its parent)
  };
  int build_range(int first, int count, std::vector<Eigen::Vector3d>& centroids);
  void fit(int box);

  std::vector<int> triangles_;            // rows of the boundary kept
  std::vector<int> slot_of_row_;          // per boundary row: its index in triangles_, or -1
  std::vector<Eigen::Matrix3d> corners_;  // per kept triangle, columns: its vertices
  std::vector<int> order_;                // kept triangles in leaf order
  std::vector<Box> boxes_;                // depth first: every child after its parent
};

}  // namespace liver_sim
