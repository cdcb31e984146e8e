#include "scenarios.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>

#include "liver_sim/geometry/node_positions.h"

namespace liver_sim {
namespace {

// The boundary node of the rest mesh nearest to p.
int nearest_surface_node(const TetMesh& mesh, const Eigen::Vector3d& p) {
  const Eigen::MatrixX3i F = boundary_triangles(mesh.T);
  int best = -1;
  double best_distance = std::numeric_limits<double>::infinity();
  for (int t = 0; t < F.rows(); ++t)
    for (int j = 0; j < 3; ++j) {
      const double d = (mesh.V.row(F(t, j)).transpose() - p).norm();
      if (d < best_distance) best_distance = d, best = F(t, j);
    }
  return best;
}

LoadOptions force(const Eigen::Vector3d& total, const Region& region) {
  LoadOptions f;
  f.kind = LoadOptions::Kind::Force;
  f.vector = total;
  f.region = region;
  return f;
}

Region sphere(const Eigen::Vector3d& centre, double radius) {
  Region r;
  r.kind = Region::Kind::Sphere;
  r.center = centre;
  r.radius = radius;
  return r;
}

Region box(const Eigen::Vector3d& min, const Eigen::Vector3d& max) {
  Region r;
  r.kind = Region::Kind::Box;
  r.min = min;
  r.max = max;
  return r;
}

}  // namespace

SyntheticCloud render_surface_cloud(const Eigen::VectorXd& x, const Eigen::MatrixX3i& boundary, const CameraView& view) {
  std::mt19937 rng(view.seed);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  std::normal_distribution<double> gauss(0.0, 1.0);
  // Camera frame: z along the view axis.
  const Eigen::Vector3d axis = (view.target - view.eye).normalized();
  const Eigen::Vector3d side = axis.unitOrthogonal(), up = axis.cross(side);
  auto to_camera = [&](const Eigen::Vector3d& p) {
    const Eigen::Vector3d d = p - view.eye;
    return Eigen::Vector3d(d.dot(side), d.dot(up), d.dot(axis));
  };
  // Depth buffer over the front faces; the image spans the whole surface as seen from the eye.
  double extent = 0;
  for (int i = 0; i < x.size(); i += 3) {
    const Eigen::Vector3d c = to_camera(x.segment<3>(i));
    if (c.z() > 0) extent = std::max({extent, std::abs(c.x() / c.z()), std::abs(c.y() / c.z())});
  }
  const int size = 512;
  const double scale = (size / 2 - 1) / std::max(extent, 1e-9);
  std::vector<double> depth(size * size, std::numeric_limits<double>::infinity());
  auto pixel = [&](const Eigen::Vector3d& c) {
    return Eigen::Vector2d(size / 2 + scale * c.x() / c.z(), size / 2 + scale * c.y() / c.z());
  };
  std::vector<char> front(boundary.rows(), 0);
  double total_area = 0;
  std::vector<double> area(boundary.rows());
  for (int t = 0; t < boundary.rows(); ++t) {
    const Eigen::Vector3d a = node(x, boundary(t, 0)), b = node(x, boundary(t, 1)), c = node(x, boundary(t, 2));
    const Eigen::Vector3d n = (b - a).cross(c - a);
    area[t] = 0.5 * n.norm();
    total_area += area[t];
    Eigen::Vector3d cam[3] = {to_camera(a), to_camera(b), to_camera(c)};
    if (n.dot(view.eye - a) <= 0 || cam[0].z() <= 0 || cam[1].z() <= 0 || cam[2].z() <= 0) continue;
    front[t] = 1;
    const Eigen::Vector2d p0 = pixel(cam[0]), p1 = pixel(cam[1]), p2 = pixel(cam[2]);
    const int u_lo = std::max(0, static_cast<int>(std::floor(std::min({p0.x(), p1.x(), p2.x()}))));
    const int u_hi = std::min(size - 1, static_cast<int>(std::ceil(std::max({p0.x(), p1.x(), p2.x()}))));
    const int v_lo = std::max(0, static_cast<int>(std::floor(std::min({p0.y(), p1.y(), p2.y()}))));
    const int v_hi = std::min(size - 1, static_cast<int>(std::ceil(std::max({p0.y(), p1.y(), p2.y()}))));
    const double det = (p1 - p0).x() * (p2 - p0).y() - (p1 - p0).y() * (p2 - p0).x();
    if (std::abs(det) < 1e-12) continue;
    for (int v = v_lo; v <= v_hi; ++v)
      for (int u = u_lo; u <= u_hi; ++u) {
        const Eigen::Vector2d q(u + 0.5, v + 0.5);
        const double l1 = ((q - p0).x() * (p2 - p0).y() - (q - p0).y() * (p2 - p0).x()) / det;
        const double l2 = ((p1 - p0).x() * (q - p0).y() - (p1 - p0).y() * (q - p0).x()) / det;
        if (l1 < 0 || l2 < 0 || l1 + l2 > 1) continue;
        const double z = (1 - l1 - l2) * cam[0].z() + l1 * cam[1].z() + l2 * cam[2].z();
        double& d = depth[v * size + u];
        d = std::min(d, z);
      }
  }
  // Uniform samples over the whole surface (their count measures area); the seen ones are kept.
  const double per_sample = view.spacing * view.spacing;
  std::vector<std::pair<double, Eigen::Vector3d>> seen;  // angle from the axis, point
  long samples = 0;
  for (int t = 0; t < boundary.rows(); ++t) {
    const double expected = area[t] / per_sample;
    const long count = static_cast<long>(expected) + (uniform(rng) < expected - std::floor(expected));
    samples += count;
    if (!front[t]) continue;
    const Eigen::Vector3d a = node(x, boundary(t, 0)), b = node(x, boundary(t, 1)), c = node(x, boundary(t, 2));
    for (long k = 0; k < count; ++k) {
      const double r1 = std::sqrt(uniform(rng)), r2 = uniform(rng);
      const Eigen::Vector3d p = (1 - r1) * a + r1 * (1 - r2) * b + r1 * r2 * c;
      const Eigen::Vector3d cam = to_camera(p);
      const Eigen::Vector2d q = pixel(cam);
      const int u = std::clamp(static_cast<int>(q.x()), 0, size - 1), v = std::clamp(static_cast<int>(q.y()), 0, size - 1);
      // Hidden when something lies in front by more than the depth a pixel spans here.
      const double slack = 2.0 * cam.z() / scale + 1e-4;
      if (cam.z() > depth[v * size + u] + slack) continue;
      seen.emplace_back(std::acos(std::clamp(cam.normalized().z(), -1.0, 1.0)), p);
    }
  }
  std::sort(seen.begin(), seen.end(), [](const auto& l, const auto& r) { return l.first < r.first; });
  const size_t wanted = static_cast<size_t>(std::llround(view.visible_fraction * samples));
  seen.resize(std::min(seen.size(), wanted));
  SyntheticCloud out;
  out.visible_fraction = samples > 0 ? static_cast<double>(seen.size()) / samples : 0.0;
  Eigen::Vector3d low = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity()), high = -low;
  for (const auto& s : seen) {
    const Eigen::Vector3d p = s.second + view.noise * Eigen::Vector3d(gauss(rng), gauss(rng), gauss(rng));
    low = low.cwiseMin(s.second);
    high = high.cwiseMax(s.second);
    out.cloud.push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));
  }
  if (view.outlier_fraction > 0 && !seen.empty()) {
    out.outliers = static_cast<int>(std::llround(view.outlier_fraction / (1 - view.outlier_fraction) * seen.size()));
    low.array() -= 0.02;
    high.array() += 0.02;
    for (int k = 0; k < out.outliers; ++k) {
      const Eigen::Vector3d p = low + (high - low).cwiseProduct(Eigen::Vector3d(uniform(rng), uniform(rng), uniform(rng)));
      out.cloud.push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));
    }
  }
  out.cloud.width = out.cloud.size();
  out.cloud.height = 1;
  return out;
}

LoadOptions underside_lift(const TetMesh& mesh, double newtons) {
  const Eigen::Vector3d low = mesh.V.colwise().minCoeff().transpose(), high = mesh.V.colwise().maxCoeff().transpose();
  LoadOptions lift;
  lift.kind = LoadOptions::Kind::Force;
  lift.vector = Eigen::Vector3d(0, 0, newtons);
  Region underside;
  underside.kind = Region::Kind::Box;
  // The right lobe: the lowest 40% of x (LPS: the patient's right at -x).
  underside.min = Eigen::Vector3d(low.x() - 1e-3, low.y() - 1e-3, low.z() - 1e-3);
  underside.max = Eigen::Vector3d(high.x() - 0.6 * (high.x() - low.x()), high.y() + 1e-3, low.z() + 0.25 * (high.z() - low.z()));
  lift.region = underside;
  return lift;
}

CameraView front_view(const Eigen::VectorXd& x) {
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  for (int i = 0; i < x.size(); i += 3) centre += x.segment<3>(i);
  centre /= x.size() / 3;
  CameraView view;
  view.eye = centre + 0.25 * Eigen::Vector3d(0.0, -1.0, 0.6).normalized();
  view.target = centre;
  return view;
}

const std::vector<std::string>& surgical_scenario_names() {
  static const std::vector<std::string> names{"lift", "press", "breathing", "pneumoperitoneum"};
  return names;
}

SurgicalScenario surgical_scenario(const std::string& name, const TetMesh& mesh) {
  const Eigen::Vector3d low = mesh.V.colwise().minCoeff().transpose(), high = mesh.V.colwise().maxCoeff().transpose();
  const Eigen::Vector3d span = high - low;
  SurgicalScenario s;
  s.name = name;
  if (name == "lift") {
    s.loads.push_back(underside_lift(mesh, 5.0));
    // The retractor's blade under the lifted lobe, its shaft leaving anteriorly and down.
    const int tip = nearest_surface_node(mesh, Eigen::Vector3d(low.x() + 0.2 * span.x(), low.y() + 0.5 * span.y(), low.z() - 0.05));
    s.instruments.push_back({tip, mesh.V.row(tip).transpose() + Eigen::Vector3d(0.02, -0.25, -0.06), 5e-3});
  } else if (name == "press") {
    // Over the tumour (right lobe, anterior face), pressing posterior and a little down.
    const int tip = nearest_surface_node(mesh, Eigen::Vector3d(low.x() + 0.25 * span.x(), low.y() - 0.1, low.z() + 0.45 * span.z()));
    const Eigen::Vector3d contact = mesh.V.row(tip).transpose();
    s.loads.push_back(force(2.0 * Eigen::Vector3d(0.0, 1.0, -0.3).normalized(), sphere(contact, 0.012)));
    s.instruments.push_back({tip, contact + 0.2 * Eigen::Vector3d(-0.3, -1.0, 0.5).normalized(), 5e-3});
  } else if (name == "breathing") {
    s.loads.push_back(force(4.0 * Eigen::Vector3d(0.0, -0.3, -1.0).normalized(),
                            box(Eigen::Vector3d(low.x() - 1e-3, low.y() - 1e-3, high.z() - 0.25 * span.z()), high.array() + 1e-3)));
  } else if (name == "pneumoperitoneum") {
    LoadOptions p;
    p.kind = LoadOptions::Kind::Pressure;
    p.pressure = 300.0;
    p.region = box(low.array() - 1e-3, Eigen::Vector3d(high.x() + 1e-3, low.y() + 0.3 * span.y(), high.z() + 1e-3));
    s.loads.push_back(p);
  } else {
    throw std::invalid_argument("unknown surgical scenario '" + name + "' (lift, press, breathing, pneumoperitoneum)");
  }
  return s;
}

std::vector<LoadOptions> scaled(const std::vector<LoadOptions>& loads, double s) {
  std::vector<LoadOptions> out = loads;
  for (LoadOptions& l : out) {
    l.vector *= s;
    l.pressure *= s;
  }
  return out;
}

std::vector<InstrumentShaft> instrument_shafts(const SurgicalScenario& scenario, const Eigen::VectorXd& x,
                                               const Eigen::MatrixX3i& boundary) {
  std::vector<InstrumentShaft> shafts;
  for (const VisibleInstrument& v : scenario.instruments) {
    Eigen::Vector3d normal = Eigen::Vector3d::Zero();  // area-weighted, of the triangles at the node
    for (int t = 0; t < boundary.rows(); ++t)
      if (boundary(t, 0) == v.node || boundary(t, 1) == v.node || boundary(t, 2) == v.node)
        normal += (node(x, boundary(t, 1)) - node(x, boundary(t, 0))).cross(node(x, boundary(t, 2)) - node(x, boundary(t, 0)));
    shafts.push_back({node(x, v.node) + v.radius * normal.normalized(), v.trocar, v.radius});
  }
  return shafts;
}

DepthCamera front_depth_camera(const Eigen::VectorXd& x) {
  const CameraView view = front_view(x);
  DepthCamera camera;
  camera.eye = view.eye;
  camera.target = view.target;
  return camera;
}

}  // namespace liver_sim
