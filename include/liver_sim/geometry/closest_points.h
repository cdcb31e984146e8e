// Closest points between points, segments and triangles (Ericson, Real-Time Collision Detection,
// 5.1), ROS-free: what contact detection and registration ask of the surface's triangles.
#pragma once

#include <Eigen/Core>

namespace liver_sim {

// The closest point of triangle (a, b, c) to p: its barycentric weights.
Eigen::Vector3d closest_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                    const Eigen::Vector3d& c);

// The closest points of segments p0-p1 and q0-q1: their parameters s and t in [0, 1]
// (p0 + s (p1 - p0), q0 + t (q1 - q0)); for parallel segments one pair of them.
Eigen::Vector2d closest_between_segments(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, const Eigen::Vector3d& q0,
                                         const Eigen::Vector3d& q1);

// The closest points of segment p0-p1 and triangle (a, b, c): the segment's parameter s in
// [0, 1] and the triangle's barycentric weights (where the segment crosses the triangle, that
// crossing).
struct SegmentTriangle {
  double s = 0;
  Eigen::Vector3d weights = Eigen::Vector3d(1, 0, 0);
};
SegmentTriangle closest_segment_triangle(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, const Eigen::Vector3d& a,
                                         const Eigen::Vector3d& b, const Eigen::Vector3d& c);

}  // namespace liver_sim
