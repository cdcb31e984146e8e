// An aspiration tube: a wall between `inner_radius` and `outer_radius` from the opening at the
// tip to `length` back along +z; `suction` acts on the tissue surface inside the lumen.
#include <algorithm>
#include <limits>

#include "liver_sim/geometry/closest_points.h"
#include "shapes.h"

namespace liver_sim {
namespace {

class Tube final : public InstrumentShape {
 public:
  SurfaceDistance distance(const InstrumentOptions& o, const Eigen::Isometry3d& pose,
                           const Eigen::Vector3d& x) const override {
    // In the plane (rho, z) of the point the wall is the rectangle [r_in, r_out] x [0, L].
    const Eigen::Vector3d local = pose.inverse() * x;
    const double rho = local.head<2>().norm();
    const Eigen::Vector3d radial =
        rho > 1e-12 * o.outer_radius ? Eigen::Vector3d(local.x() / rho, local.y() / rho, 0) : Eigen::Vector3d::UnitX();
    const Eigen::Vector2d centre(0.5 * (o.inner_radius + o.outer_radius), 0.5 * o.length);
    const Eigen::Vector2d half(0.5 * (o.outer_radius - o.inner_radius), 0.5 * o.length);
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

  // The wall is not convex: a local search from the best of the corners, edge midpoints and
  // centroid, by steps along -normal projected onto the triangle.
  TrianglePoint deepest_point(const InstrumentOptions& o, const Eigen::Isometry3d& pose, const Eigen::Vector3d& a,
                              const Eigen::Vector3d& b, const Eigen::Vector3d& c) const override {
    auto at = [&](const Eigen::Vector3d& w) { return Eigen::Vector3d(w[0] * a + w[1] * b + w[2] * c); };
    Eigen::Vector3d best = Eigen::Vector3d(1, 0, 0);
    double least = std::numeric_limits<double>::infinity();
    for (const Eigen::Vector3d& w :
         {Eigen::Vector3d(1, 0, 0), Eigen::Vector3d(0, 1, 0), Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(0.5, 0.5, 0),
          Eigen::Vector3d(0, 0.5, 0.5), Eigen::Vector3d(0.5, 0, 0.5), Eigen::Vector3d(1.0 / 3, 1.0 / 3, 1.0 / 3)}) {
      const double d = distance(o, pose, at(w)).distance;
      if (d < least) {
        least = d;
        best = w;
      }
    }
    double step = 0.25 * (o.outer_radius - o.inner_radius);
    for (int k = 0; k < 12; ++k) {
      const SurfaceDistance here = distance(o, pose, at(best));
      const Eigen::Vector3d w = closest_on_triangle(at(best) - std::max(step, here.distance) * here.normal, a, b, c);
      if (distance(o, pose, at(w)).distance < here.distance) {
        best = w;
      } else {
        step *= 0.5;
      }
    }
    return triangle_point(*this, o, pose, a, b, c, best);
  }

  // A flat rim touches the surface at its nodes.
  double sample_spacing(const InstrumentOptions&) const override { return std::numeric_limits<double>::infinity(); }
  double size(const InstrumentOptions& o) const override { return o.outer_radius - o.inner_radius; }
  double travel(const InstrumentOptions& o, const Eigen::Isometry3d& from, const Eigen::Isometry3d& to) const override {
    return rod_travel(o.length, from, to);
  }

  bool sucks() const override { return true; }
  // On the surface inside the lumen as the step starts: the triangles whose centroid lies within
  // the lumen's cross-section (radius < inner_radius) and in front of the opening by at most
  // the wall thickness, on a surface facing into the tube.
  void suction(const InstrumentOptions& o, const Eigen::Isometry3d& pose, const Eigen::MatrixX3i& boundary,
               const Eigen::VectorXd& x, PressureLoad& load) const override {
    load.pressure = -o.suction;
    load.triangles.clear();
    if (!o.enabled || load.pressure == 0) return;
    const Eigen::Isometry3d inverse = pose.inverse();
    const double wall = o.outer_radius - o.inner_radius;
    for (int f = 0; f < boundary.rows(); ++f) {
      const Eigen::Vector3d a = x.segment<3>(3 * boundary(f, 0)), b = x.segment<3>(3 * boundary(f, 1)),
                            c = x.segment<3>(3 * boundary(f, 2));
      const Eigen::Vector3d local = inverse * ((a + b + c) / 3);
      const Eigen::Vector3d outward_normal = (b - a).cross(c - a);
      if (local.head<2>().norm() < o.inner_radius && local.z() > -wall && local.z() < o.length &&
          outward_normal.dot(pose.linear().col(2)) > 0)
        load.triangles.push_back(f);
    }
  }

  void draw(const InstrumentOptions& o, const Eigen::Isometry3d& pose, std::vector<InstrumentPart>& parts) const override {
    using P = InstrumentPart::Primitive;
    using R = InstrumentPart::Role;
    parts.push_back(part(P::Cylinder, pose * Eigen::Translation3d(0, 0, 0.5 * o.length),
                         Eigen::Vector3d(2 * o.outer_radius, 2 * o.outer_radius, o.length), R::Wall));
    // The lumen 0.1 mm farther back: its opening is not drawn in the wall's plane.
    parts.push_back(part(P::Cylinder, pose * Eigen::Translation3d(0, 0, 0.5 * o.length + 1e-4),
                         Eigen::Vector3d(2 * o.inner_radius, 2 * o.inner_radius, o.length), R::Lumen));
  }
};

}  // namespace

const InstrumentShape& tube_shape() {
  static const Tube tube;
  return tube;
}

}  // namespace liver_sim
