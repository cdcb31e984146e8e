#include "depth_camera.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>

#include "liver_sim/geometry/node_positions.h"

namespace liver_sim {
namespace {

constexpr double kInfinity = std::numeric_limits<double>::infinity();

// Range along the unit ray (o, d) to a capsule (segment a-b, radius r), or infinity: the
// cylinder's body if the ray enters it between the ends, else the nearer end sphere.
double ray_capsule(const Eigen::Vector3d& o, const Eigen::Vector3d& d, const Eigen::Vector3d& a,
                   const Eigen::Vector3d& b, double r) {
  const Eigen::Vector3d ba = b - a, oa = o - a;
  const double baba = ba.dot(ba), bard = ba.dot(d), baoa = ba.dot(oa);
  const double qa = baba - bard * bard, qb = baba * d.dot(oa) - baoa * bard, qc = baba * oa.dot(oa) - baoa * baoa - r * r * baba;
  const double h = qb * qb - qa * qc;
  if (h < 0) return kInfinity;  // misses the infinite cylinder, so the capsule too
  if (qa > 1e-12 * baba) {
    const double t = (-qb - std::sqrt(h)) / qa, y = baoa + t * bard;
    if (y > 0 && y < baba) return t > 0 ? t : kInfinity;
  }
  double best = kInfinity;
  for (const Eigen::Vector3d* c : {&a, &b}) {
    const Eigen::Vector3d oc = o - *c;
    const double sb = d.dot(oc), sh = sb * sb - (oc.dot(oc) - r * r);
    if (sh < 0) continue;
    const double t = -sb - std::sqrt(sh);
    if (t > 0) best = std::min(best, t);
  }
  return best;
}

}  // namespace

double depth_sigma(const DepthCamera& camera, double depth) {
  const double s = depth / camera.reference_depth;
  return camera.depth_noise * s * s;
}

DepthCloud render_depth_cloud(const Eigen::VectorXd& x, const Eigen::MatrixX3i& boundary,
                              const std::vector<InstrumentShaft>& instruments, const DepthCamera& camera) {
  if (camera.width < 8 || camera.height < 8 || !(camera.horizontal_fov > 0 && camera.horizontal_fov < M_PI) ||
      !(camera.reference_depth > 0))
    throw std::invalid_argument("depth camera: needs >= 8 x 8 pixels, a field of view in (0, pi), reference depth > 0");
  std::mt19937 rng(camera.seed);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  std::normal_distribution<double> gauss(0.0, 1.0);
  const Eigen::Vector3d axis = (camera.target - camera.eye).normalized();
  const Eigen::Vector3d right = axis.cross(camera.up).normalized(), down = axis.cross(right);
  const int W = camera.width, H = camera.height, n = W * H;
  const double f = 0.5 * W / std::tan(0.5 * camera.horizontal_fov), cx = 0.5 * W, cy = 0.5 * H;
  // A pixel's ray with unit component along the axis: its parameter is the depth z.
  auto ray = [&](double u, double v) { return Eigen::Vector3d(axis + ((u - cx) / f) * right + ((v - cy) / f) * down); };

  // Depth buffer: depth along the axis and what was hit (a boundary triangle, or -2 - k for
  // instrument k).
  std::vector<double> depth(n, kInfinity);
  std::vector<int> hit(n, -1);
  for (int t = 0; t < boundary.rows(); ++t) {
    const Eigen::Vector3d a = node(x, boundary(t, 0)), b = node(x, boundary(t, 1)), c = node(x, boundary(t, 2));
    const Eigen::Vector3d e1 = b - a, e2 = c - a;
    if (e1.cross(e2).dot(camera.eye - a) <= 0) continue;  // back face
    double u_lo = kInfinity, u_hi = -kInfinity, v_lo = kInfinity, v_hi = -kInfinity;
    bool behind = false;
    for (const Eigen::Vector3d* p : {&a, &b, &c}) {
      const Eigen::Vector3d q = *p - camera.eye;
      const double z = q.dot(axis);
      if (z <= 1e-6) behind = true;
      const double u = cx + f * q.dot(right) / z, v = cy + f * q.dot(down) / z;
      u_lo = std::min(u_lo, u), u_hi = std::max(u_hi, u), v_lo = std::min(v_lo, v), v_hi = std::max(v_hi, v);
    }
    if (behind) continue;
    const int i0 = std::max(0, static_cast<int>(std::floor(u_lo - 0.5))), i1 = std::min(W - 1, static_cast<int>(std::ceil(u_hi)));
    const int j0 = std::max(0, static_cast<int>(std::floor(v_lo - 0.5))), j1 = std::min(H - 1, static_cast<int>(std::ceil(v_hi)));
    for (int j = j0; j <= j1; ++j)
      for (int i = i0; i <= i1; ++i) {
        // Moeller-Trumbore with the unnormalised ray: the parameter is the depth.
        const Eigen::Vector3d d = ray(i + 0.5, j + 0.5);
        const Eigen::Vector3d p = d.cross(e2);
        const double det = e1.dot(p);
        if (std::abs(det) < 1e-18) continue;
        const Eigen::Vector3d s = camera.eye - a;
        // A little slack: rays through a shared edge meet one of its triangles despite round-off.
        constexpr double slack = 1e-12;
        const double l1 = s.dot(p) / det;
        if (l1 < -slack || l1 > 1 + slack) continue;
        const Eigen::Vector3d q = s.cross(e1);
        const double l2 = d.dot(q) / det;
        if (l2 < -slack || l1 + l2 > 1 + slack) continue;
        const double z = e2.dot(q) / det;
        const int k = j * W + i;
        if (z > 0 && z < depth[k]) depth[k] = z, hit[k] = t;
      }
  }
  for (size_t m = 0; m < instruments.size(); ++m)
    for (int j = 0; j < H; ++j)
      for (int i = 0; i < W; ++i) {
        const Eigen::Vector3d d = ray(i + 0.5, j + 0.5);
        const double range = ray_capsule(camera.eye, d.normalized(), instruments[m].tip, instruments[m].trocar,
                                         instruments[m].radius);
        const double z = range / d.norm();
        const int k = j * W + i;
        if (z < depth[k]) depth[k] = z, hit[k] = -2 - static_cast<int>(m);
      }

  // Every pixel that sees something, with its angle from the axis; tissue pixels with their
  // footprint on the surface (the field of view is measured in area) and their fate.
  enum class Fate { Returned, Edge, Grazing };
  struct Pixel {
    int index;
    double off_axis;   // rad
    double area;       // m^2 of tissue surface, 0 for instruments
    double incidence;  // rad (tissue)
    Fate fate;
  };
  std::vector<Pixel> seen;
  double total_area = 0;
  for (int t = 0; t < boundary.rows(); ++t)
    total_area += 0.5 * (node(x, boundary(t, 1)) - node(x, boundary(t, 0))).cross(node(x, boundary(t, 2)) - node(x, boundary(t, 0))).norm();
  for (int j = 0; j < H; ++j)
    for (int i = 0; i < W; ++i) {
      const int k = j * W + i;
      if (hit[k] == -1) continue;
      const Eigen::Vector3d d = ray(i + 0.5, j + 0.5);
      const double off_axis = std::acos(std::clamp(1.0 / d.norm(), -1.0, 1.0));
      bool edge = false;
      for (const auto& [di, dj] : {std::pair{1, 0}, {-1, 0}, {0, 1}, {0, -1}}) {
        const int ii = i + di, jj = j + dj;
        if (ii < 0 || jj < 0 || ii >= W || jj >= H) continue;
        edge |= !(std::abs(depth[jj * W + ii] - depth[k]) <= camera.edge_jump);
      }
      if (hit[k] <= -2) {
        seen.push_back({k, off_axis, 0.0, 0.0, edge ? Fate::Edge : Fate::Returned});
        continue;
      }
      const int t = hit[k];
      const Eigen::Vector3d a = node(x, boundary(t, 0));
      const Eigen::Vector3d normal = (node(x, boundary(t, 1)) - a).cross(node(x, boundary(t, 2)) - a).normalized();
      const double cos_incidence = std::clamp(-normal.dot(d.normalized()), 1e-2, 1.0);
      const double incidence = std::acos(cos_incidence);
      Fate fate = Fate::Returned;
      if (edge) fate = Fate::Edge;
      else if (incidence > camera.grazing_limit ||
               (incidence > camera.grazing_start &&
                uniform(rng) < (incidence - camera.grazing_start) / (camera.grazing_limit - camera.grazing_start)))
        fate = Fate::Grazing;
      // A pixel's solid angle is cos^3(off_axis) / f^2; at range z / cos(off_axis) on a surface
      // tilted by the incidence it covers z^2 cos(off_axis) / (f^2 cos(incidence)).
      seen.push_back({k, off_axis, depth[k] * depth[k] * std::cos(off_axis) / (f * f * cos_incidence), incidence, fate});
    }
  // The field of view: the cone about the axis in which the tissue in sight (returned or lost to
  // the sensor's defects) covers the requested share of the surface.
  std::sort(seen.begin(), seen.end(), [](const Pixel& l, const Pixel& r) { return l.off_axis < r.off_axis; });
  double in_view = 0, returned_area = 0;
  size_t kept = 0;
  for (; kept < seen.size() && in_view < camera.visible_fraction * total_area; ++kept) {
    in_view += seen[kept].area;
    if (seen[kept].fate == Fate::Returned) returned_area += seen[kept].area;
  }
  seen.resize(kept);
  DepthCloud out;
  out.visible_fraction = in_view / total_area;
  out.returned_fraction = returned_area / total_area;
  std::vector<Pixel> returns;
  for (const Pixel& p : seen) {
    const bool tissue = hit[p.index] >= 0;
    if (p.fate == Fate::Returned) returns.push_back(p);
    else if (tissue) ++(p.fate == Fate::Edge ? out.edge_dropped : out.grazing_dropped);
  }
  // Blood: films over discs around random tissue returns.
  std::vector<Eigen::Vector3d> blood;
  std::vector<int> tissue;
  for (size_t r = 0; r < returns.size(); ++r)
    if (hit[returns[r].index] >= 0) tissue.push_back(static_cast<int>(r));
  for (int b = 0; b < camera.blood_patches && !tissue.empty(); ++b) {
    const Pixel& r = returns[tissue[static_cast<size_t>(uniform(rng) * tissue.size()) % tissue.size()]];
    blood.push_back(camera.eye + depth[r.index] * ray(r.index % W + 0.5, r.index / W + 0.5));
  }
  std::sort(returns.begin(), returns.end(), [](const Pixel& l, const Pixel& r) { return l.index < r.index; });
  for (const Pixel& r : returns) {
    const int i = r.index % W, j = r.index / W;
    double z = depth[r.index];
    const bool on_tissue = hit[r.index] >= 0;
    if (on_tissue) {
      const Eigen::Vector3d p = camera.eye + z * ray(i + 0.5, j + 0.5);
      for (const Eigen::Vector3d& c : blood)
        if ((p - c).norm() < camera.blood_radius) {
          // The ray meets the film's surface blood_depth / cos(incidence) earlier.
          z -= camera.blood_depth / std::max(std::cos(r.incidence), 0.3) / ray(i + 0.5, j + 0.5).norm();
          ++out.blood_points;
          break;
        }
    }
    z += depth_sigma(camera, z) * gauss(rng);
    const Eigen::Vector3d p = camera.eye + z * ray(i + 0.5 + camera.lateral_noise * gauss(rng), j + 0.5 + camera.lateral_noise * gauss(rng));
    out.cloud.push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));
    ++(on_tissue ? out.tissue_points : out.instrument_points);
  }
  out.cloud.width = out.cloud.size();
  out.cloud.height = 1;
  return out;
}

}  // namespace liver_sim
