#include "insilico_case.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>

#include "liver_sim/geometry/surface_locator.h"
#include "liver_sim/io/mesh_io.h"
#include "liver_sim/io/surface_io.h"

namespace liver_sim {

std::string insilico_folder(const std::string& fallback) {
  const char* set = std::getenv("LIVER_SIM_INSILICO");
  return set && *set ? std::string(set) : fallback;
}

std::optional<InsilicoCase> load_insilico_case(const std::string& folder, std::string* why) {
  // The partial views: every .stl but the two whole boundaries, by name.
  std::vector<std::string> views;
  std::error_code error;
  for (const auto& entry : std::filesystem::directory_iterator(folder, error)) {
    const std::filesystem::path& p = entry.path();
    if (p.extension() == ".stl" && p.stem() != "initial-surface" && p.stem() != "deformed-surface") views.push_back(p.stem());
  }
  std::sort(views.begin(), views.end());
  for (const char* f : {"initial-volume.vtk", "deformed-volume.vtk"})
    if (!std::ifstream(folder + "/" + f)) {
      if (why) *why = folder + "/" + f + " is absent (the Open-CAS in-silico case, CC BY-NC-ND, is not distributed with liver_sim)";
      return std::nullopt;
    }
  if (views.empty()) {
    if (why) *why = folder + " holds no partial view (.stl)";
    return std::nullopt;
  }
  InsilicoCase c;
  c.initial = read_mesh(folder + "/initial-volume.vtk", 1e-3);
  const TetMesh deformed = read_mesh(folder + "/deformed-volume.vtk", 1e-3);
  if (deformed.V.rows() != c.initial.V.rows() || deformed.T != c.initial.T)
    throw MeshError(folder + ": the deformed volume does not share the initial volume's nodes and cells");
  c.deformed = deformed.V;
  const Eigen::MatrixX3i F = boundary_triangles(c.initial.T);
  std::vector<char> on_surface(c.initial.V.rows(), 0);
  for (int t = 0; t < F.rows(); ++t)
    for (int j = 0; j < 3; ++j) on_surface[F(t, j)] = 1;
  SurfaceLocator surface;
  surface.build(SurfaceMesh{c.initial.V, F});
  for (int i = 0; i < c.initial.V.rows(); ++i)
    if (!on_surface[i]) {
      c.targets.push_back(i);
      c.depth.push_back(surface.closest(c.initial.V.row(i).transpose()).distance);
    }
  for (const std::string& v : views) {
    c.view_names.push_back(v);
    c.views.push_back(read_surface(folder + "/" + v + ".stl", 1e-3));
  }
  return c;
}

pcl::PointCloud<pcl::PointXYZ> sample_surface(const SurfaceMesh& s, double spacing, double noise, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  std::normal_distribution<double> gauss(0.0, 1.0);
  pcl::PointCloud<pcl::PointXYZ> cloud;
  for (int t = 0; t < s.F.rows(); ++t) {
    const Eigen::Vector3d a = s.V.row(s.F(t, 0)), b = s.V.row(s.F(t, 1)), c = s.V.row(s.F(t, 2));
    const double expected = 0.5 * (b - a).cross(c - a).norm() / (spacing * spacing);
    const long count = static_cast<long>(expected) + (uniform(rng) < expected - std::floor(expected));
    for (long k = 0; k < count; ++k) {
      double u = uniform(rng), v = uniform(rng);
      if (u + v > 1) u = 1 - u, v = 1 - v;
      const Eigen::Vector3d p = a + u * (b - a) + v * (c - a) + noise * Eigen::Vector3d(gauss(rng), gauss(rng), gauss(rng));
      cloud.push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));
    }
  }
  return cloud;
}

TreSummary summarise_tre(const std::vector<double>& errors, const std::vector<double>& depth) {
  TreSummary s;
  if (errors.empty()) return s;
  auto stats = [](std::vector<double> v, double& mean, double& p95, double& max) {
    std::sort(v.begin(), v.end());
    mean = 0;
    for (double e : v) mean += e / v.size();
    p95 = v[std::min(v.size() - 1, static_cast<size_t>(std::ceil(0.95 * v.size())) - 1)];  // nearest rank
    max = v.back();
  };
  stats(errors, s.mean, s.p95, s.max);
  std::vector<size_t> order(errors.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return depth[a] > depth[b]; });
  const size_t deep = std::max<size_t>(1, order.size() / 10);
  std::vector<double> deepest;
  for (size_t k = 0; k < deep; ++k) deepest.push_back(errors[order[k]]);
  s.deep_from = depth[order[deep - 1]];
  stats(deepest, s.deep_mean, s.deep_p95, s.deep_max);
  return s;
}

double chi_square3_cdf(double x) {
  if (!(x > 0)) return 0.0;
  return std::erf(std::sqrt(x / 2)) - std::sqrt(2 * x / M_PI) * std::exp(-x / 2);
}

Calibration calibration(std::vector<double> d2) {
  Calibration c;
  c.count = static_cast<int>(d2.size());
  if (d2.empty()) return c;
  std::sort(d2.begin(), d2.end());
  const size_t n = d2.size();
  c.median = n % 2 ? d2[n / 2] : 0.5 * (d2[n / 2 - 1] + d2[n / 2]);
  for (size_t i = 0; i < n; ++i) {
    c.inside_95 += (d2[i] <= 7.814727903251178) / static_cast<double>(n);
    const double F = chi_square3_cdf(d2[i]);
    c.ks = std::max({c.ks, std::abs(F - static_cast<double>(i) / n), std::abs(F - static_cast<double>(i + 1) / n)});
  }
  return c;
}

}  // namespace liver_sim
