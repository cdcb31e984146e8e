#include "mesh_marker.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <set>

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

// rviz's orbit view puts its camera at (cos yaw cos pitch, sin yaw cos pitch, sin pitch) from its
// focal point: config/liver_sim.rviz's Yaw 5.0 and Pitch 0.55.
const Eigen::Vector3d kViewerDirection(std::cos(5.0) * std::cos(0.55), std::sin(5.0) * std::cos(0.55), std::sin(0.55));

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
      depth[f] = (x.segment<3>(3 * F(f, 0)) + x.segment<3>(3 * F(f, 1)) + x.segment<3>(3 * F(f, 2))).dot(kViewerDirection);
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
          static_cast<float>(kAmbient + (1 - kAmbient) * std::max(0.0, normals.row(node).dot(kViewerDirection)));
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

std::string target_label(const TrackedTarget& target) {
  if (target.kind != TrackedTarget::Kind::Bifurcation || target.name.empty()) return target.name;
  // "<vessel> bifurcation <k>": the vessel's initial and k.
  const size_t number = target.name.find_last_not_of("0123456789");
  return std::string(1, static_cast<char>(std::toupper(static_cast<unsigned char>(target.name[0])))) +
         (number == std::string::npos ? target.name : target.name.substr(number + 1));
}

std::vector<std::pair<size_t, std::string>> labelled_targets(const std::vector<TrackedTarget>& targets) {
  const std::string centre = "_centre";
  std::set<std::string> stems;  // of the probes named <stem>_centre
  for (const TrackedTarget& t : targets)
    if (t.kind == TrackedTarget::Kind::Probe && t.name.size() > centre.size() &&
        t.name.compare(t.name.size() - centre.size(), centre.size(), centre) == 0)
      stems.insert(t.name.substr(0, t.name.size() - centre.size()));
  std::vector<std::pair<size_t, std::string>> out;
  for (size_t i = 0; i < targets.size(); ++i) {
    const TrackedTarget& t = targets[i];
    const size_t underscore = t.name.rfind('_');
    const std::string stem = underscore == std::string::npos ? "" : t.name.substr(0, underscore);
    if (t.kind == TrackedTarget::Kind::Probe && stems.count(stem)) {
      if (t.name == stem + centre) out.emplace_back(i, stem);
    } else {
      out.emplace_back(i, target_label(t));
    }
  }
  return out;
}

double label_half_width(const std::string& text, double height) { return 0.3 * height * text.size() + 0.1 * height; }

LabelLayout label_positions(const std::vector<Eigen::Vector3d>& anchors, const std::vector<std::string>& texts,
                            double height, const Eigen::VectorXd& organ) {
  // The view's axes: across (right on the screen), up, and toward the viewer.
  const Eigen::Vector3d toward = kViewerDirection.normalized();
  const Eigen::Vector3d across = Eigen::Vector3d::UnitZ().cross(toward).normalized();
  const Eigen::Vector3d up = toward.cross(across);
  double left = INFINITY, right = -INFINITY, front = -INFINITY;
  for (int i = 0; i + 2 < organ.size(); i += 3) {
    const Eigen::Vector3d p = organ.segment<3>(i);
    left = std::min(left, p.dot(across));
    right = std::max(right, p.dot(across));
    front = std::max(front, p.dot(toward));
  }
  const double middle = 0.5 * (left + right), line = 1.3 * height;
  LabelLayout layout;
  layout.at.resize(anchors.size());
  layout.inner.resize(anchors.size());
  for (int side : {-1, 1}) {
    std::vector<size_t> column;
    for (size_t i = 0; i < anchors.size(); ++i)
      if ((anchors[i].dot(across) < middle) == (side < 0)) column.push_back(i);
    std::sort(column.begin(), column.end(), [&](size_t a, size_t b) { return anchors[a].dot(up) < anchors[b].dot(up); });
    // Each label as near its anchor's height as the others let it: labels that would come closer
    // than a line form a block, a line apart, at their anchors' mean height less their offsets in
    // it (the least squares), merged with the block below until it is a line above that one.
    struct Block {
      size_t first, size;
      double sum;  // of the anchors' heights less their offsets in the block
      double bottom() const { return sum / size; }
    };
    std::vector<Block> blocks;
    for (size_t k = 0; k < column.size(); ++k) {
      blocks.push_back({k, 1, anchors[column[k]].dot(up)});
      while (blocks.size() > 1) {
        Block &below = blocks[blocks.size() - 2], &above = blocks.back();
        if (below.bottom() + below.size * line <= above.bottom()) break;
        below.sum += above.sum - above.size * below.size * line;
        below.size += above.size;
        blocks.pop_back();
      }
    }
    const double edge = side < 0 ? left - height : right + height;  // the labels' inner ends
    for (const Block& b : blocks)
      for (size_t k = b.first; k < b.first + b.size; ++k) {
        const size_t i = column[k];
        const Eigen::Vector3d inner = edge * across + (b.bottom() + (k - b.first) * line) * up + front * toward;
        layout.inner[i] = inner;
        layout.at[i] = inner + side * label_half_width(texts[i], height) * across;
      }
  }
  return layout;
}

void append_target_names(const std::vector<TrackedTarget>& targets, const Eigen::VectorXd& organ,
                         const std_msgs::Header& header, visualization_msgs::MarkerArray& markers) {
  constexpr double kHeight = 0.006;  // m, text height: readable in the package's view of a liver
  const std::vector<std::pair<size_t, std::string>> labelled = labelled_targets(targets);
  std::vector<Eigen::Vector3d> anchors;
  std::vector<std::string> texts;
  for (const auto& [index, text] : labelled) {
    anchors.push_back(targets[index].position);
    texts.push_back(text);
  }
  const LabelLayout layout = label_positions(anchors, texts, kHeight, organ);
  visualization_msgs::Marker leaders;
  leaders.header = header;
  leaders.ns = "target_leaders";
  leaders.type = visualization_msgs::Marker::LINE_LIST;
  leaders.action = visualization_msgs::Marker::ADD;
  leaders.pose.orientation.w = 1;
  leaders.scale.x = 0.0005;  // m, line width
  leaders.color.a = 1.0f;
  for (size_t k = 0; k < labelled.size(); ++k) {
    visualization_msgs::Marker m;
    m.header = header;
    m.ns = "target_names";
    m.id = static_cast<int>(labelled[k].first);
    m.type = visualization_msgs::Marker::TEXT_VIEW_FACING;
    m.action = visualization_msgs::Marker::ADD;
    m.pose.position.x = layout.at[k].x();
    m.pose.position.y = layout.at[k].y();
    m.pose.position.z = layout.at[k].z();
    m.pose.orientation.w = 1;
    m.scale.z = kHeight;
    const bool vessel = targets[labelled[k].first].kind == TrackedTarget::Kind::Bifurcation;
    m.color.r = vessel ? 0.75f : 1.0f;  // the targets' hues, lightened: bifurcations blue, probes red
    m.color.g = vessel ? 0.8f : 0.7f;
    m.color.b = vessel ? 1.0f : 0.7f;
    m.color.a = 1.0f;
    m.text = texts[k];
    markers.markers.push_back(m);
    for (const Eigen::Vector3d& p : {anchors[k], layout.inner[k]}) {
      geometry_msgs::Point q;
      q.x = p.x();
      q.y = p.y();
      q.z = p.z();
      leaders.points.push_back(q);
      leaders.colors.push_back(m.color);
    }
  }
  if (!leaders.points.empty()) markers.markers.push_back(leaders);
}

// Where the legend and the axes go: in front of and below the model's rest box, under its middle,
// which the package's view shows below the organ (the target labels take its sides).
namespace {
Eigen::Vector3d under_the_middle(const Eigen::AlignedBox3d& box) {
  return Eigen::Vector3d(box.center().x(), box.min().y() - 0.02, box.min().z() - 0.015);
}
}  // namespace

void append_orientation_axes(const Eigen::AlignedBox3d& box, const std_msgs::Header& header,
                             visualization_msgs::MarkerArray& markers) {
  const double length = 0.2 * box.sizes().minCoeff();
  const Eigen::Vector3d origin = under_the_middle(box) - Eigen::Vector3d(0.085, 0, 0);  // left of the legend
  const char* names[3] = {"L", "P", "S"};  // LPS: +x the patient's left, +y posterior, +z superior
  for (int axis = 0; axis < 3; ++axis) {
    visualization_msgs::Marker m;
    m.header = header;
    m.ns = "orientation";
    m.id = axis;
    m.type = visualization_msgs::Marker::ARROW;
    m.action = visualization_msgs::Marker::ADD;
    m.pose.orientation.w = 1;
    const Eigen::Vector3d tip = origin + length * Eigen::Vector3d::Unit(axis);
    for (const Eigen::Vector3d& p : {origin, tip}) {
      geometry_msgs::Point q;
      q.x = p.x();
      q.y = p.y();
      q.z = p.z();
      m.points.push_back(q);
    }
    m.scale.x = 0.1 * length;   // shaft diameter
    m.scale.y = 0.2 * length;   // head diameter
    m.scale.z = 0.25 * length;  // head length
    m.color.r = axis == 0 ? 1.0f : 0.3f;  // x red, y green, z blue, as rviz draws axes
    m.color.g = axis == 1 ? 1.0f : 0.3f;
    m.color.b = axis == 2 ? 1.0f : 0.3f;
    m.color.a = 1.0f;
    markers.markers.push_back(m);
    m.id = 3 + axis;
    m.type = visualization_msgs::Marker::TEXT_VIEW_FACING;
    m.points.clear();
    const Eigen::Vector3d label = origin + 1.35 * length * Eigen::Vector3d::Unit(axis);
    m.pose.position.x = label.x();
    m.pose.position.y = label.y();
    m.pose.position.z = label.z();
    m.scale.x = m.scale.y = 0;
    m.scale.z = 0.008;  // m, text height
    m.text = names[axis];
    markers.markers.push_back(m);
  }
}

void append_colour_legend(const Eigen::AlignedBox3d& box, double scale_max, const std_msgs::Header& header,
                          visualization_msgs::MarkerArray& markers) {
  constexpr int kCubes = 9;       // 0, 1/8, ..., 1 of the scale: labels at 0, 1/4, 1/2, 3/4, 1
  constexpr double kCube = 0.01;  // m, along the bar
  const Eigen::Vector3d base = under_the_middle(box) - Eigen::Vector3d(0.5 * (kCubes - 1) * kCube, 0, 0);
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
    m.pose.position.x = base.x() + k * kCube;
    m.pose.position.y = base.y();
    m.pose.position.z = base.z();
    m.scale.x = kCube;
    m.scale.y = m.scale.z = 0.6 * kCube;
    m.color = displacement_colour(u, scale_max);
    markers.markers.push_back(m);
    if (k % 2 == 0) {
      char label[32];
      std::snprintf(label, sizeof label, k == kCubes - 1 ? ">= %.3g" : "%.3g", u * 1e3);
      text(kCubes + k, base + Eigen::Vector3d(k * kCube, 0, -0.011), label);
    }
  }
  text(2 * kCubes, base + Eigen::Vector3d((kCubes - 0.5) * kCube + 0.03, 0, 0), "displacement (mm)");
}

void append_annotations(const std::vector<TrackedTarget>& targets, const Eigen::VectorXd& organ,
                        const Eigen::AlignedBox3d& rest, double scale_max, const std_msgs::Header& header,
                        visualization_msgs::MarkerArray& markers) {
  append_target_names(targets, organ, header, markers);
  append_orientation_axes(rest, header, markers);
  append_colour_legend(rest, scale_max, header, markers);
}

}  // namespace liver_sim
