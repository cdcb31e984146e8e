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

void fill_mesh_marker(const LiverModel& model, double scale_max, double alpha, visualization_msgs::Marker& marker) {
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
      marker.colors[3 * f + k].a = static_cast<float>(alpha);
    }
}

void fill_vessel_marker(const LiverModel& model, visualization_msgs::Marker& marker) {
  // Portal (violet), hepatic (blue), then repeating.
  static const float palette[3][3] = {{0.6f, 0.2f, 0.8f}, {0.2f, 0.4f, 1.0f}, {0.9f, 0.3f, 0.3f}};
  marker.type = visualization_msgs::Marker::LINE_LIST;
  marker.action = visualization_msgs::Marker::ADD;
  marker.pose.orientation.w = 1.0;
  marker.scale.x = 0.002;  // m, line width
  marker.color.a = 1.0f;
  const int beams = model.num_beams();
  marker.points.resize(2 * beams);
  marker.colors.resize(2 * beams);
  for (int e = 0; e < beams; ++e) {
    const float* rgb = palette[model.beam_vessel(e) % 3];
    for (int end = 0; end < 2; ++end) {
      const Eigen::Vector3d p = model.vessel_node_position(model.beam_segments()(e, end));
      geometry_msgs::Point& q = marker.points[2 * e + end];
      q.x = p.x();
      q.y = p.y();
      q.z = p.z();
      std_msgs::ColorRGBA& c = marker.colors[2 * e + end];
      c.r = rgb[0];
      c.g = rgb[1];
      c.b = rgb[2];
      c.a = 1.0f;
    }
  }
}

}  // namespace liver_sim
