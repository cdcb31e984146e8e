#include "mesh_marker.h"

#include <algorithm>
#include <cmath>

namespace liver_sim {

std_msgs::ColorRGBA displacement_colour(double u, double scale_max) {
  static const double stops[5][3] = {{0, 0, 1}, {0, 1, 1}, {0, 1, 0}, {1, 1, 0}, {1, 0, 0}};
  const double t = std::isfinite(u) ? std::clamp(u / scale_max, 0.0, 1.0) * 4.0 : 4.0;
  const int k = std::min(static_cast<int>(t), 3);
  const double f = t - k;
  std_msgs::ColorRGBA c;
  c.r = static_cast<float>((1 - f) * stops[k][0] + f * stops[k + 1][0]);
  c.g = static_cast<float>((1 - f) * stops[k][1] + f * stops[k + 1][1]);
  c.b = static_cast<float>((1 - f) * stops[k][2] + f * stops[k + 1][2]);
  c.a = 1.0f;
  return c;
}

void fill_mesh_marker(const LiverModel& model, double scale_max, visualization_msgs::Marker& marker) {
  marker.type = visualization_msgs::Marker::TRIANGLE_LIST;
  marker.action = visualization_msgs::Marker::ADD;
  marker.pose.orientation.w = 1.0;
  marker.scale.x = marker.scale.y = marker.scale.z = 1.0;
  marker.color.a = 1.0f;  // rviz multiplies vertex alpha by it
  const Eigen::MatrixX3i& F = model.boundary();
  const Eigen::VectorXd& x = model.positions();
  const Eigen::MatrixX3d& X = model.mesh().V;
  marker.points.resize(3 * F.rows());
  marker.colors.resize(3 * F.rows());
  for (int f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      const int node = F(f, k);
      geometry_msgs::Point& p = marker.points[3 * f + k];
      p.x = x[3 * node];
      p.y = x[3 * node + 1];
      p.z = x[3 * node + 2];
      const double u = (x.segment<3>(3 * node) - X.row(node).transpose()).norm();
      marker.colors[3 * f + k] = displacement_colour(u, scale_max);
    }
}

}  // namespace liver_sim
