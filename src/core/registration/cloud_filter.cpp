#include "liver_sim/registration/cloud_filter.h"

#include <algorithm>
#include <cmath>
#include <optional>
#include <sstream>
#include <stdexcept>

namespace liver_sim {
namespace {

bool finite(const pcl::PointXYZ& p) { return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z); }

}  // namespace

std::string cloud_size_error(uint64_t points) {
  if (points <= kMaxCloudPoints) return "";
  return "a cloud of " + std::to_string(points) + " points: at most " + std::to_string(kMaxCloudPoints) + " are taken";
}

namespace {

constexpr int kMaxVoxelsPerAxis = 1 << 20;  // a 64-bit key holds three indices

Eigen::Array3d voxel_cells(double size, const Eigen::AlignedBox3d& box) {
  return (box.max() / size).array().floor() - (box.min() / size).array().floor() + 1;
}

}  // namespace

std::string voxel_grid_error(double voxel, const Eigen::AlignedBox3d& box) {
  // Negated: a voxel so fine that the box's cell indices overflow to infinity (inf - inf: NaN)
  // is refused too.
  if (!(voxel > 0) || (voxel_cells(voxel, box) <= kMaxVoxelsPerAxis).all()) return "";
  std::ostringstream m;
  m << "a voxel of " << voxel << " m is too fine for a box of " << box.sizes().maxCoeff() << " m: at most "
    << kMaxVoxelsPerAxis << " voxels along an axis";
  return m.str();
}

namespace {

// The centroids of a cloud's points per voxel of a grid aligned at multiples of `size` (m), as
// PCL's VoxelGrid gives them. Its voxels are found by hashing, in one pass: VoxelGrid sorts
// every point by its voxel (with the crop, 10.6 ms against 1.4 ms for 100,000 points in 5 mm
// voxels on one core).
class VoxelCentroids {
 public:
  // Points to come lie in `box` (throws std::invalid_argument with voxel_grid_error's refusal).
  VoxelCentroids(double size, const Eigen::AlignedBox3d& box) : size_(size) {
    const std::string too_fine = voxel_grid_error(size, box);
    if (!too_fine.empty()) throw std::invalid_argument(too_fine);
    lower_ = (box.min() / size).array().floor();
    const Eigen::Array3d cells = voxel_cells(size, box);
    row_ = static_cast<int64_t>(cells.x());
    layer_ = row_ * static_cast<int64_t>(cells.y());
    rehash(1024);
  }
  void add(const Eigen::Vector3d& p) {
    const Eigen::Array3d cell = (p / size_).array().floor() - lower_;
    const int64_t key = static_cast<int64_t>(cell.x()) + row_ * static_cast<int64_t>(cell.y()) +
                        layer_ * static_cast<int64_t>(cell.z());
    size_t i = bucket(key);
    while (keys_[i] >= 0 && keys_[i] != key) i = (i + 1) & (keys_.size() - 1);
    if (keys_[i] < 0) {
      keys_[i] = key;
      voxel_[i] = static_cast<int>(sums_.size());
      sums_.emplace_back(Eigen::Vector3d::Zero(), 0);
      if (2 * sums_.size() > keys_.size()) {  // at most half full: short probes
        rehash(2 * keys_.size());
        i = bucket(key);
        while (keys_[i] != key) i = (i + 1) & (keys_.size() - 1);
      }
    }
    auto& [sum, count] = sums_[voxel_[i]];
    sum += p;
    ++count;
  }
  // The centroids, in the order of their voxels (x fastest, then y, then z).
  void centroids(pcl::PointCloud<pcl::PointXYZ>& out) const {
    std::vector<std::pair<int64_t, int>> order;
    order.reserve(sums_.size());
    for (size_t i = 0; i < keys_.size(); ++i)
      if (keys_[i] >= 0) order.emplace_back(keys_[i], voxel_[i]);
    std::sort(order.begin(), order.end());
    out.clear();
    out.reserve(order.size());
    for (const auto& [key, v] : order) {
      const Eigen::Vector3d c = sums_[v].first / sums_[v].second;
      out.push_back(pcl::PointXYZ(c.x(), c.y(), c.z()));
    }
  }

 private:
  size_t bucket(int64_t key) const {
    return static_cast<size_t>((static_cast<uint64_t>(key) * 0x9E3779B97F4A7C15ull) >> shift_);
  }
  void rehash(size_t capacity) {
    std::vector<int64_t> keys(capacity, -1);
    std::vector<int> voxel(capacity);
    keys_.swap(keys);
    voxel_.swap(voxel);
    shift_ = 64 - static_cast<int>(std::log2(static_cast<double>(capacity)));
    for (size_t j = 0; j < keys.size(); ++j) {
      if (keys[j] < 0) continue;
      size_t i = bucket(keys[j]);
      while (keys_[i] >= 0) i = (i + 1) & (capacity - 1);
      keys_[i] = keys[j];
      voxel_[i] = voxel[j];
    }
  }
  double size_;
  Eigen::Array3d lower_;
  int64_t row_ = 0, layer_ = 0;
  std::vector<int64_t> keys_;  // open addressing, linear probing; -1: empty
  std::vector<int> voxel_;     // per bucket: its index in sums_
  int shift_ = 0;
  std::vector<std::pair<Eigen::Vector3d, int>> sums_;  // per voxel: its points' sum and count
};

}  // namespace

int prepare_cloud(const pcl::PointCloud<pcl::PointXYZ>& in, const Eigen::Isometry3d& transform,
                  const Eigen::AlignedBox3d& box, double voxel, int max_points, pcl::PointCloud<pcl::PointXYZ>& out) {
  const std::string too_large = cloud_size_error(in.size());
  if (!too_large.empty()) throw std::invalid_argument(too_large);
  std::optional<VoxelCentroids> grid;
  if (voxel > 0) grid.emplace(voxel, box);
  out.clear();
  if (!grid) out.reserve(in.size());
  int finite_points = 0;
  for (const pcl::PointXYZ& q : in) {
    if (!finite(q)) continue;
    ++finite_points;
    const Eigen::Vector3d p = transform * Eigen::Vector3d(q.x, q.y, q.z);
    if (!box.contains(p)) continue;
    if (grid)
      grid->add(p);
    else
      out.push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));
  }
  if (grid) grid->centroids(out);
  if (static_cast<int>(out.size()) > max_points) {
    const double stride = static_cast<double>(out.size()) / max_points;
    pcl::PointCloud<pcl::PointXYZ> kept;
    for (int i = 0; i < max_points; ++i) kept.push_back(out[static_cast<size_t>(i * stride)]);
    out.swap(kept);
  }
  return finite_points;
}

}  // namespace liver_sim
