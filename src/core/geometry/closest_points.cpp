#include "liver_sim/geometry/closest_points.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>

namespace liver_sim {

namespace {

// The weights of the closest point of (a, b, c) to p on its edges alone: for a triangle with no
// area (coincident or collinear corners), where the face's and some edges' formulas divide by 0.
Eigen::Vector3d closest_on_edges(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                 const Eigen::Vector3d& c) {
  const Eigen::Vector3d corner[3] = {a, b, c};
  Eigen::Vector3d best(1, 0, 0);
  double nearest = (p - a).squaredNorm();
  for (int i = 0; i < 3; ++i) {
    const int j = (i + 1) % 3;
    const Eigen::Vector3d e = corner[j] - corner[i];
    const double length = e.squaredNorm();
    const double t = length > 0 ? std::clamp(e.dot(p - corner[i]) / length, 0.0, 1.0) : 0.0;
    const double d = (p - corner[i] - t * e).squaredNorm();
    if (d < nearest) {
      nearest = d;
      best.setZero();
      best[i] = 1 - t;
      best[j] = t;
    }
  }
  return best;
}

}  // namespace

Eigen::Vector3d closest_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                    const Eigen::Vector3d& c) {
  // Voronoi regions of the vertices, then the edges, else the face (Ericson, Real-Time
  // Collision Detection, 5.1.5). Each division is by a squared edge length or twice the area
  // squared, up to rounding: a triangle without area goes to its edges.
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return {1, 0, 0};
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return {0, 1, 0};
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    if (!(d1 - d3 > 0)) return closest_on_edges(p, a, b, c);
    const double v = d1 / (d1 - d3);
    return {1 - v, v, 0};
  }
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return {0, 0, 1};
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    if (!(d2 - d6 > 0)) return closest_on_edges(p, a, b, c);
    const double w = d2 / (d2 - d6);
    return {1 - w, 0, w};
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    if (!((d4 - d3) + (d5 - d6) > 0)) return closest_on_edges(p, a, b, c);
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return {0, 1 - w, w};
  }
  // The face: va + vb + vc is |ab x ac|^2, zero or rounding for corners (nearly) on a line.
  const double area_squared = va + vb + vc;
  if (!(area_squared > 1e-12 * ab.squaredNorm() * ac.squaredNorm())) return closest_on_edges(p, a, b, c);
  const double denominator = 1.0 / area_squared;
  const double v = vb * denominator, w = vc * denominator;
  return {1 - v - w, v, w};
}

Eigen::Vector2d closest_between_segments(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, const Eigen::Vector3d& q0,
                                         const Eigen::Vector3d& q1) {
  const Eigen::Vector3d d1 = p1 - p0, d2 = q1 - q0, r = p0 - q0;
  const double a = d1.squaredNorm(), e = d2.squaredNorm(), f = d2.dot(r);
  if (a <= 0 && e <= 0) return {0, 0};
  if (a <= 0) return {0, std::clamp(f / e, 0.0, 1.0)};
  const double c = d1.dot(r);
  if (e <= 0) return {std::clamp(-c / a, 0.0, 1.0), 0};
  const double b = d1.dot(d2), denominator = a * e - b * b;
  // Parallel segments (denominator 0): any s, here 0.
  double s = denominator > 0 ? std::clamp((b * f - c * e) / denominator, 0.0, 1.0) : 0.0;
  double t = (b * s + f) / e;
  if (t < 0) {
    t = 0;
    s = std::clamp(-c / a, 0.0, 1.0);
  } else if (t > 1) {
    t = 1;
    s = std::clamp((b - c) / a, 0.0, 1.0);
  }
  return {s, t};
}

SegmentTriangle closest_segment_triangle(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, const Eigen::Vector3d& a,
                                         const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  // A crossing of the triangle's plane inside the triangle is the answer (distance 0).
  const Eigen::Vector3d n = (b - a).cross(c - a), d = p1 - p0;
  const double along = n.dot(d);
  if (along != 0) {
    const double s = n.dot(a - p0) / along;
    if (s >= 0 && s <= 1) {
      const Eigen::Vector3d q = p0 + s * d;
      const Eigen::Vector3d w = closest_on_triangle(q, a, b, c);
      if ((w[0] * a + w[1] * b + w[2] * c - q).norm() <= 1e-12 * std::sqrt(n.norm())) return {s, w};
    }
  }
  // Else the closest pair has an end of the segment or lies on an edge of the triangle.
  SegmentTriangle best;
  double best_distance = std::numeric_limits<double>::infinity();
  auto consider = [&](double s, const Eigen::Vector3d& w) {
    const double distance = (p0 + s * d - (w[0] * a + w[1] * b + w[2] * c)).squaredNorm();
    if (distance < best_distance) {
      best_distance = distance;
      best = {s, w};
    }
  };
  consider(0, closest_on_triangle(p0, a, b, c));
  consider(1, closest_on_triangle(p1, a, b, c));
  const Eigen::Vector3d corners[3] = {a, b, c};
  for (int k = 0; k < 3; ++k) {
    const Eigen::Vector2d st = closest_between_segments(p0, p1, corners[k], corners[(k + 1) % 3]);
    Eigen::Vector3d w = Eigen::Vector3d::Zero();
    w[k] = 1 - st[1];
    w[(k + 1) % 3] = st[1];
    consider(st[0], w);
  }
  return best;
}

}  // namespace liver_sim
