#include "liver_sim/contact/surface_contact.h"

#include <algorithm>
#include <cmath>

#include "liver_sim/contact/instrument_shape.h"

namespace liver_sim {

Eigen::Vector3d SurfacePoint::at(const Eigen::VectorXd& x) const {
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  for (int j = 0; j < count; ++j) p += weights[j] * x.segment<3>(3 * nodes[j]);
  return p;
}

SurfacePoint SurfacePoint::on_triangle(const Eigen::Vector3i& nodes, const Eigen::Vector3d& w) {
  SurfacePoint p;
  double sum = 0;
  for (int k = 0; k < 3; ++k) {
    if (w[k] <= 1e-9) continue;
    // Insertion in node order.
    int j = p.count++;
    for (; j > 0 && p.nodes[j - 1] > nodes[k]; --j) {
      p.nodes[j] = p.nodes[j - 1];
      p.weights[j] = p.weights[j - 1];
    }
    p.nodes[j] = nodes[k];
    p.weights[j] = w[k];
    sum += w[k];
  }
  p.weights /= sum;
  return p;
}

Eigen::Vector3d contact_rows(const SurfaceContact& c, const InstrumentSlot& in, const Eigen::VectorXd& x,
                             const Eigen::VectorXd& x_stage, Eigen::Matrix3d* frame) {
  const Eigen::Vector3d p = c.point.at(x);
  if (c.held >= 0) {
    frame->setIdentity();
    return p - in.pose * in.held_local[c.held];
  }
  const SurfaceDistance d = shape_of(in.options.type).distance(in.options, in.pose, p);
  // Tangents: any orthonormal pair (forces are carried between iterations in the world frame).
  const Eigen::Vector3d helper = std::abs(d.normal.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  const Eigen::Vector3d t1 = d.normal.cross(helper).normalized();
  frame->col(0) = d.normal;
  frame->col(1) = t1;
  frame->col(2) = d.normal.cross(t1);
  // Slip over the step: against the instrument point that was under the surface point at its start.
  const Eigen::Vector3d slip = p - in.pose * (in.pose_start.inverse() * c.point.at(x_stage));
  return Eigen::Vector3d(d.distance, frame->col(1).dot(slip), frame->col(2).dot(slip));
}

}  // namespace liver_sim
