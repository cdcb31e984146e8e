#include "liver_sim/meshing/anatomy.h"

namespace liver_sim {

Eigen::MatrixX3d to_lps(const Eigen::MatrixX3d& V, PatientFrame frame) {
  Eigen::MatrixX3d out = V;
  if (frame == PatientFrame::RAS) out.leftCols<2>() *= -1.0;
  return out;
}

Region bare_area(const SurfaceMesh& surface) {
  Eigen::Index top = 0;
  (surface.V.col(1) + surface.V.col(2)).maxCoeff(&top);
  Region r;
  r.kind = Region::Kind::Sphere;
  r.center = surface.V.row(top).transpose();
  r.radius = 0.25 * (surface.V.colwise().maxCoeff() - surface.V.colwise().minCoeff()).maxCoeff();
  return r;
}

}  // namespace liver_sim
