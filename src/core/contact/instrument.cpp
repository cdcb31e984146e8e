#include "liver_sim/contact/instrument.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "liver_sim/geometry/closest_points.h"

namespace liver_sim {
namespace {

// Nearest point of a sphere of radius r around c: along the radius, or out of the tip when at c.
SurfaceDistance around_point(const Eigen::Vector3d& x, const Eigen::Vector3d& c, double r,
                             const Eigen::Vector3d& fallback) {
  const Eigen::Vector3d d = x - c;
  const double n = d.norm();
  SurfaceDistance s;
  s.distance = n - r;
  s.normal = n > 1e-12 * r ? Eigen::Vector3d(d / n) : fallback;
  return s;
}

}  // namespace

Eigen::Isometry3d make_pose(const Eigen::Vector3d& position, const Eigen::Quaterniond& orientation) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  // Scaled without squaring: a quaternion of 1e200 is a rotation too (its norm() overflows).
  T.linear() = Eigen::Quaterniond(orientation.coeffs() / orientation.coeffs().stableNorm()).toRotationMatrix();
  T.translation() = position;
  return T;
}

SurfaceDistance surface_distance(const InstrumentOptions& shape, const Eigen::Isometry3d& pose,
                                 const Eigen::Vector3d& x) {
  const Eigen::Vector3d axis = pose.linear().col(2);
  const Eigen::Vector3d tip = pose.translation();
  switch (shape.type) {
    case InstrumentOptions::Type::Probe:
    case InstrumentOptions::Type::Grasper:
      return around_point(x, tip, shape.radius, -axis);
    case InstrumentOptions::Type::Shaft: {
      const double s = std::clamp((x - tip).dot(axis), 0.0, shape.length);
      return around_point(x, tip + s * axis, shape.radius, -axis);
    }
    case InstrumentOptions::Type::Tube: {
      // In the plane (rho, z) of the point the wall is the rectangle [r_in, r_out] x [0, L].
      const Eigen::Vector3d local = pose.inverse() * x;
      const double rho = local.head<2>().norm();
      const Eigen::Vector3d radial =
          rho > 1e-12 * shape.outer_radius ? Eigen::Vector3d(local.x() / rho, local.y() / rho, 0) : Eigen::Vector3d::UnitX();
      const Eigen::Vector2d centre(0.5 * (shape.inner_radius + shape.outer_radius), 0.5 * shape.length);
      const Eigen::Vector2d half(0.5 * (shape.outer_radius - shape.inner_radius), 0.5 * shape.length);
      const Eigen::Vector2d q(rho - centre.x(), local.z() - centre.y());
      const Eigen::Vector2d d = q.cwiseAbs() - half;
      Eigen::Vector2d n2;
      SurfaceDistance s;
      if (d.maxCoeff() > 0) {  // outside: to the nearest point of the rectangle
        const Eigen::Vector2d out = d.cwiseMax(0.0);
        s.distance = out.norm();
        n2 = Eigen::Vector2d(q.x() < 0 ? -out.x() : out.x(), q.y() < 0 ? -out.y() : out.y()) / s.distance;
      } else {  // inside: out through the nearest side
        s.distance = d.maxCoeff();
        n2 = d.x() > d.y() ? Eigen::Vector2d(q.x() < 0 ? -1 : 1, 0) : Eigen::Vector2d(0, q.y() < 0 ? -1 : 1);
      }
      s.normal = pose.linear() * (n2.x() * radial + n2.y() * Eigen::Vector3d::UnitZ());
      return s;
    }
  }
  return {};
}

TrianglePoint deepest_point(const InstrumentOptions& shape, const Eigen::Isometry3d& pose, const Eigen::Vector3d& a,
                            const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  auto at = [&](const Eigen::Vector3d& w) { return Eigen::Vector3d(w[0] * a + w[1] * b + w[2] * c); };
  TrianglePoint best;
  switch (shape.type) {
    case InstrumentOptions::Type::Probe:
    case InstrumentOptions::Type::Grasper:
      best.weights = closest_on_triangle(pose.translation(), a, b, c);
      break;
    case InstrumentOptions::Type::Shaft: {
      const Eigen::Vector3d tip = pose.translation();
      best.weights = closest_segment_triangle(tip, tip + shape.length * pose.linear().col(2), a, b, c).weights;
      break;
    }
    case InstrumentOptions::Type::Tube: {
      // The wall is not convex: a local search from the best of seven points.
      double least = std::numeric_limits<double>::infinity();
      for (const Eigen::Vector3d& w :
           {Eigen::Vector3d(1, 0, 0), Eigen::Vector3d(0, 1, 0), Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(0.5, 0.5, 0),
            Eigen::Vector3d(0, 0.5, 0.5), Eigen::Vector3d(0.5, 0, 0.5), Eigen::Vector3d(1.0 / 3, 1.0 / 3, 1.0 / 3)}) {
        const double d = surface_distance(shape, pose, at(w)).distance;
        if (d < least) {
          least = d;
          best.weights = w;
        }
      }
      double step = 0.25 * (shape.outer_radius - shape.inner_radius);
      for (int k = 0; k < 12; ++k) {
        const SurfaceDistance here = surface_distance(shape, pose, at(best.weights));
        const Eigen::Vector3d w = closest_on_triangle(at(best.weights) - std::max(step, here.distance) * here.normal, a, b, c);
        if (surface_distance(shape, pose, at(w)).distance < here.distance) {
          best.weights = w;
        } else {
          step *= 0.5;
        }
      }
      break;
    }
  }
  best.distance = surface_distance(shape, pose, at(best.weights));
  return best;
}

bool in_tube_lumen(const InstrumentOptions& tube, const Eigen::Isometry3d& pose, const Eigen::Vector3d& x,
                   const Eigen::Vector3d& outward_normal) {
  const Eigen::Vector3d local = pose.inverse() * x;
  const double wall = tube.outer_radius - tube.inner_radius;
  return local.head<2>().norm() < tube.inner_radius && local.z() > -wall && local.z() < tube.length &&
         outward_normal.dot(pose.linear().col(2)) > 0;
}

Eigen::Isometry3d pose_at(const InstrumentOptions& o, double t) {
  const auto& path = o.trajectory;
  if (path.empty()) return make_pose(o.position, o.orientation);
  if (t <= path.front().t) return make_pose(path.front().position, path.front().orientation);
  if (t >= path.back().t) return make_pose(path.back().position, path.back().orientation);
  const auto next = std::upper_bound(path.begin(), path.end(), t,
                                     [](double v, const InstrumentOptions::Keyframe& k) { return v < k.t; });
  const auto& b = *next;
  const auto& a = *(next - 1);
  const double s = (t - a.t) / (b.t - a.t);
  return make_pose((1 - s) * a.position + s * b.position,
                   a.orientation.normalized().slerp(s, b.orientation.normalized()));
}

bool closed_at(const InstrumentOptions& o, double t) {
  bool closed = o.closed;
  for (const InstrumentOptions::Keyframe& k : o.trajectory)
    if (k.t <= t && k.closed) closed = *k.closed;
  return closed;
}

}  // namespace liver_sim
