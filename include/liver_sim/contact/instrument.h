// Rigid instruments as signed distance functions (each shape's own in instrument_shape.h), and
// pose paths. ROS-free.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "liver_sim/scene/options.h"

namespace liver_sim {

// Distance from a point to the instrument's surface (m; < 0 inside it) and the outward surface
// normal at the nearest surface point (the direction in which the instrument pushes the point).
struct SurfaceDistance {
  double distance = 0;
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
};

// A point on the axis of a sphere or shaft has no nearest direction: it is pushed along the
// instrument's -z (out of its tip).
SurfaceDistance surface_distance(const InstrumentOptions& shape, const Eigen::Isometry3d& pose,
                                 const Eigen::Vector3d& x);

// The point of triangle (a, b, c) deepest inside the instrument, or nearest to it when outside:
// where surface_distance is least over the triangle, as barycentric weights, with that distance
// and normal. The whole triangle is at least that far from the instrument. Exact for the sphere
// and the shaft (closest points to the tip or the axis); for the tube, the best of the corners,
// edge midpoints and centroid, improved by steps along -normal projected onto the triangle.
struct TrianglePoint {
  Eigen::Vector3d weights = Eigen::Vector3d(1, 0, 0);
  SurfaceDistance distance;
};
TrianglePoint deepest_point(const InstrumentOptions& shape, const Eigen::Isometry3d& pose, const Eigen::Vector3d& a,
                            const Eigen::Vector3d& b, const Eigen::Vector3d& c);

// Pose at time t: the fixed pose without a trajectory; else linear in position and spherical
// linear in orientation between keyframes, held before the first and after the last.
Eigen::Isometry3d pose_at(const InstrumentOptions& o, double t);

// Grasper state at time t: `closed`, changed by each keyframe with a `closed` value at or
// before t.
bool closed_at(const InstrumentOptions& o, double t);

Eigen::Isometry3d make_pose(const Eigen::Vector3d& position, const Eigen::Quaterniond& orientation);

}  // namespace liver_sim
