#include "stylus.h"

#include <pcl/kdtree/kdtree_flann.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>
#include <unordered_map>
#include <vector>

#include "liver_sim/geometry/node_positions.h"

namespace liver_sim {
namespace {

// Points spread uniformly over the triangles' area, about `spacing` apart: per triangle its
// expected count, rounded at random.
pcl::PointCloud<pcl::PointXYZ> area_samples(const Eigen::VectorXd& x, const Eigen::MatrixX3i& F, double spacing,
                                            std::mt19937& rng) {
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  pcl::PointCloud<pcl::PointXYZ> samples;
  for (int t = 0; t < F.rows(); ++t) {
    const Eigen::Vector3d a = node(x, F(t, 0)), b = node(x, F(t, 1)), c = node(x, F(t, 2));
    const double expected = 0.5 * (b - a).cross(c - a).norm() / (spacing * spacing);
    const long count = static_cast<long>(expected) + (uniform(rng) < expected - std::floor(expected));
    for (long k = 0; k < count; ++k) {
      double u = uniform(rng), v = uniform(rng);
      if (u + v > 1) u = 1 - u, v = 1 - v;
      const Eigen::Vector3d p = a + u * (b - a) + v * (c - a);
      samples.push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));
    }
  }
  return samples;
}

// Marks the samples within `reach` of `points`; returns how many were newly marked.
long mark_covered(const pcl::KdTreeFLANN<pcl::PointXYZ>& samples, const std::vector<Eigen::Vector3d>& points, double reach,
                  std::vector<char>& covered) {
  long added = 0;
  std::vector<int> near;
  std::vector<float> squared;
  for (const Eigen::Vector3d& p : points) {
    samples.radiusSearch(pcl::PointXYZ(p.x(), p.y(), p.z()), reach, near, squared);
    for (int i : near) added += !covered[i], covered[i] = 1;
  }
  return added;
}

}  // namespace

double area_coverage(const Eigen::VectorXd& x, const Eigen::MatrixX3i& boundary, const pcl::PointCloud<pcl::PointXYZ>& cloud,
                     double reach, unsigned seed) {
  std::mt19937 rng(seed);
  const pcl::PointCloud<pcl::PointXYZ> samples = area_samples(x, boundary, reach / 4, rng);
  if (samples.empty()) return 0.0;
  pcl::KdTreeFLANN<pcl::PointXYZ> tree;
  tree.setInputCloud(samples.makeShared());
  std::vector<char> covered(samples.size(), 0);
  std::vector<Eigen::Vector3d> points;
  for (const pcl::PointXYZ& p : cloud) points.push_back(p.getVector3fMap().cast<double>());
  return static_cast<double>(mark_covered(tree, points, reach, covered)) / samples.size();
}

StylusData swab_surface(const Eigen::VectorXd& x, const Eigen::MatrixX3i& F, const StylusSweep& sweep) {
  if (!(sweep.coverage > 0 && sweep.coverage <= 1) || !(sweep.reach > 0) || !(sweep.spacing > 0) || !(sweep.noise >= 0) ||
      !(sweep.raster > 0) || !(sweep.anterior.norm() > 0))
    throw std::invalid_argument("stylus: coverage in (0, 1], reach, spacing and raster > 0, noise >= 0, an anterior direction");
  std::mt19937 rng(sweep.seed);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  std::normal_distribution<double> gauss(0.0, 1.0);
  const Eigen::Vector3d a = sweep.anterior.normalized(), e1 = a.unitOrthogonal(), e2 = a.cross(e1);
  // The surface seen from the anterior side: per raster cell across the plane, the most
  // anterior point of the triangles facing that way.
  std::unordered_map<long long, Eigen::Vector3d> front;
  auto key = [](long i, long j) { return (static_cast<long long>(i) << 32) ^ (j & 0xffffffffLL); };
  const double h = sweep.raster;
  for (int t = 0; t < F.rows(); ++t) {
    const Eigen::Vector3d p0 = node(x, F(t, 0)), p1 = node(x, F(t, 1)), p2 = node(x, F(t, 2));
    if ((p1 - p0).cross(p2 - p0).dot(a) <= 0) continue;
    const Eigen::Vector2d q0(p0.dot(e1), p0.dot(e2)), q1(p1.dot(e1), p1.dot(e2)), q2(p2.dot(e1), p2.dot(e2));
    const double det = (q1 - q0).x() * (q2 - q0).y() - (q1 - q0).y() * (q2 - q0).x();
    if (std::abs(det) < 1e-18) continue;
    const long i0 = static_cast<long>(std::floor(std::min({q0.x(), q1.x(), q2.x()}) / h));
    const long i1 = static_cast<long>(std::ceil(std::max({q0.x(), q1.x(), q2.x()}) / h));
    const long j0 = static_cast<long>(std::floor(std::min({q0.y(), q1.y(), q2.y()}) / h));
    const long j1 = static_cast<long>(std::ceil(std::max({q0.y(), q1.y(), q2.y()}) / h));
    for (long i = i0; i <= i1; ++i)
      for (long j = j0; j <= j1; ++j) {
        const Eigen::Vector2d q((i + 0.5) * h, (j + 0.5) * h);
        const double l1 = ((q - q0).x() * (q2 - q0).y() - (q - q0).y() * (q2 - q0).x()) / det;
        const double l2 = ((q1 - q0).x() * (q - q0).y() - (q1 - q0).y() * (q - q0).x()) / det;
        if (l1 < 0 || l2 < 0 || l1 + l2 > 1) continue;
        const Eigen::Vector3d p = (1 - l1 - l2) * p0 + l1 * p1 + l2 * p2;
        auto [it, added] = front.emplace(key(i, j), p);
        if (!added && p.dot(a) > it->second.dot(a)) it->second = p;
      }
  }
  StylusData data;
  if (front.empty()) return data;
  std::vector<Eigen::Vector3d> surface;
  for (const auto& [k, p] : front) surface.push_back(p);
  std::sort(surface.begin(), surface.end(), [](const Eigen::Vector3d& p, const Eigen::Vector3d& q) {
    return std::lexicographical_compare(p.data(), p.data() + 3, q.data(), q.data() + 3);  // an order of its own, not the hash's
  });
  const pcl::PointCloud<pcl::PointXYZ> samples = area_samples(x, F, sweep.reach / 4, rng);
  pcl::KdTreeFLANN<pcl::PointXYZ> tree;
  tree.setInputCloud(samples.makeShared());
  std::vector<char> covered(samples.size(), 0);
  long covered_count = 0;
  while (data.strokes < sweep.max_strokes && covered_count < sweep.coverage * samples.size()) {
    const double heading = M_PI * uniform(rng);
    const Eigen::Vector3d u = std::cos(heading) * e1 + std::sin(heading) * e2, along = a.cross(u);
    double lo = std::numeric_limits<double>::infinity(), hi = -lo;
    for (const Eigen::Vector3d& p : surface) lo = std::min(lo, p.dot(u)), hi = std::max(hi, p.dot(u));
    const double offset = lo + (hi - lo) * (0.05 + 0.9 * uniform(rng));
    std::vector<std::pair<double, Eigen::Vector3d>> line;
    for (const Eigen::Vector3d& p : surface)
      if (std::abs(p.dot(u) - offset) <= 0.5 * h) line.push_back({p.dot(along), p});
    ++data.strokes;
    if (line.empty()) continue;
    std::sort(line.begin(), line.end(), [](const auto& p, const auto& q) { return p.first < q.first; });
    // A stretch of the cut: from half to all of it.
    const double length = line.back().first - line.front().first, kept = length * (0.5 + 0.5 * uniform(rng));
    const double from = line.front().first + (length - kept) * uniform(rng);
    std::vector<Eigen::Vector3d> stroke;
    for (const auto& [t, p] : line)
      if (t >= from && t <= from + kept && (stroke.empty() || (p - stroke.back()).norm() >= sweep.spacing)) stroke.push_back(p);
    for (Eigen::Vector3d& p : stroke) p += sweep.noise * Eigen::Vector3d(gauss(rng), gauss(rng), gauss(rng));
    covered_count += mark_covered(tree, stroke, sweep.reach, covered);
    for (const Eigen::Vector3d& p : stroke) data.cloud.push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));
  }
  data.coverage = samples.empty() ? 0.0 : static_cast<double>(covered_count) / samples.size();
  return data;
}

}  // namespace liver_sim
