#include "mesh_marker.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numeric>

namespace liver_sim {

std_msgs::ColorRGBA displacement_colour(double u, double scale_max) {
  // Unmoved tissue in a pale tissue tone, on which the shading shows the shape; motion in warm
  // colours: yellow, orange, red.
  static const double stops[5][3] = {{0.80, 0.70, 0.64}, {0.95, 0.85, 0.30}, {1.0, 0.55, 0.10}, {0.90, 0.20, 0.05}, {0.70, 0.0, 0.10}};
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

const Eigen::Vector3d kLightDirection = Eigen::Vector3d(0.24, -0.82, 0.52).normalized();

Eigen::MatrixX3d vertex_normals(const Eigen::MatrixX3i& F, const Eigen::VectorXd& x) {
  Eigen::MatrixX3d n = Eigen::MatrixX3d::Zero(x.size() / 3, 3);
  for (int f = 0; f < F.rows(); ++f) {
    const Eigen::Vector3d a = x.segment<3>(3 * F(f, 0)), b = x.segment<3>(3 * F(f, 1)), c = x.segment<3>(3 * F(f, 2));
    const Eigen::RowVector3d area_normal = 0.5 * (b - a).cross(c - a).transpose();  // length: the area
    for (int k = 0; k < 3; ++k) n.row(F(f, k)) += area_normal;
  }
  for (int i = 0; i < n.rows(); ++i)
    if (n.row(i).squaredNorm() > 0) n.row(i).normalize();
  return n;
}

void fill_mesh_marker(const LiverModel& model, const Eigen::VectorXd& reference, double scale_max, double alpha,
                      visualization_msgs::Marker& marker) {
  // Diffuse light with an ambient share, so that faces turned away stay readable.
  constexpr double kAmbient = 0.35;
  marker.type = visualization_msgs::Marker::TRIANGLE_LIST;
  marker.action = visualization_msgs::Marker::ADD;
  marker.pose.orientation.w = 1.0;
  marker.scale.x = marker.scale.y = marker.scale.z = 1.0;
  marker.color.a = 1.0f;  // rviz multiplies vertex alpha by it
  const Eigen::MatrixX3i& F = model.boundary();
  const Eigen::VectorXd& x = model.positions();
  const Eigen::MatrixX3d normals = vertex_normals(F, x);
  std::vector<int> order(F.rows());
  std::iota(order.begin(), order.end(), 0);
  if (alpha < 1) {
    // Farthest from the viewer first: a translucent marker's triangles are blended in order.
    std::vector<double> depth(F.rows());
    for (int f = 0; f < F.rows(); ++f)
      depth[f] = (x.segment<3>(3 * F(f, 0)) + x.segment<3>(3 * F(f, 1)) + x.segment<3>(3 * F(f, 2))).dot(kLightDirection);
    std::sort(order.begin(), order.end(), [&](int a, int b) { return depth[a] < depth[b]; });
  }
  marker.points.resize(3 * F.rows());
  marker.colors.resize(3 * F.rows());
  for (int i = 0; i < F.rows(); ++i)
    for (int k = 0; k < 3; ++k) {
      const int node = F(order[i], k);
      geometry_msgs::Point& p = marker.points[3 * i + k];
      p.x = x[3 * node];
      p.y = x[3 * node + 1];
      p.z = x[3 * node + 2];
      std_msgs::ColorRGBA& c = marker.colors[3 * i + k];
      c = displacement_colour((x.segment<3>(3 * node) - reference.segment<3>(3 * node)).norm(), scale_max);
      const float light =
          static_cast<float>(kAmbient + (1 - kAmbient) * std::max(0.0, normals.row(node).dot(kLightDirection)));
      c.r *= light;
      c.g *= light;
      c.b *= light;
      c.a = static_cast<float>(alpha);
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

void append_target_names(const std::vector<TrackedTarget>& targets, const std_msgs::Header& header,
                         visualization_msgs::MarkerArray& markers) {
  for (size_t i = 0; i < targets.size(); ++i) {
    visualization_msgs::Marker m;
    m.header = header;
    m.ns = "target_names";
    m.id = static_cast<int>(i);
    m.type = visualization_msgs::Marker::TEXT_VIEW_FACING;
    m.action = visualization_msgs::Marker::ADD;
    m.pose.position.x = targets[i].position.x();
    m.pose.position.y = targets[i].position.y();
    m.pose.position.z = targets[i].position.z() + 0.004;
    m.pose.orientation.w = 1;
    m.scale.z = 0.003;  // m, text height
    m.color.r = m.color.g = m.color.b = m.color.a = 1.0f;
    m.text = targets[i].name;
    markers.markers.push_back(m);
  }
}

void append_colour_legend(const Eigen::AlignedBox3d& box, double scale_max, const std_msgs::Header& header,
                          visualization_msgs::MarkerArray& markers) {
  constexpr int kCubes = 9;  // 0, 1/8, ..., 1 of the scale: labels at 0, 1/4, 1/2, 3/4, 1
  const double height = box.sizes().z();
  const double cube = height / kCubes;
  const Eigen::Vector3d base(box.max().x() + 0.015, box.min().y(), box.min().z() + 0.5 * cube);
  auto marker = [&](int id, int type) {
    visualization_msgs::Marker m;
    m.header = header;
    m.ns = "legend";
    m.id = id;
    m.type = type;
    m.action = visualization_msgs::Marker::ADD;
    m.pose.orientation.w = 1;
    return m;
  };
  auto text = [&](int id, const Eigen::Vector3d& at, const std::string& s) {
    visualization_msgs::Marker m = marker(id, visualization_msgs::Marker::TEXT_VIEW_FACING);
    m.pose.position.x = at.x();
    m.pose.position.y = at.y();
    m.pose.position.z = at.z();
    m.scale.z = 0.005;  // m, text height
    m.color.r = m.color.g = m.color.b = m.color.a = 1.0f;
    m.text = s;
    markers.markers.push_back(m);
  };
  for (int k = 0; k < kCubes; ++k) {
    const double u = scale_max * k / (kCubes - 1);
    visualization_msgs::Marker m = marker(k, visualization_msgs::Marker::CUBE);
    m.pose.position.x = base.x();
    m.pose.position.y = base.y();
    m.pose.position.z = base.z() + k * cube;
    m.scale.x = m.scale.y = 0.6 * cube;
    m.scale.z = cube;
    m.color = displacement_colour(u, scale_max);
    markers.markers.push_back(m);
    if (k % 2 == 0) {
      char label[32];
      std::snprintf(label, sizeof label, k == kCubes - 1 ? ">= %.3g" : "%.3g", u * 1e3);
      text(kCubes + k, base + Eigen::Vector3d(0.018, 0, k * cube), label);
    }
  }
  text(2 * kCubes, base + Eigen::Vector3d(0, 0, kCubes * cube), "displacement (mm)");
}

}  // namespace liver_sim
