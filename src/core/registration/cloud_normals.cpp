#include "liver_sim/registration/cloud_normals.h"

#include <pcl/kdtree/kdtree_flann.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <queue>

namespace liver_sim {

std::vector<Eigen::Vector3d> estimate_normals(const pcl::PointCloud<pcl::PointXYZ>& cloud, int neighbours,
                                              const std::optional<Eigen::Vector3d>& viewpoint) {
  const int n = static_cast<int>(cloud.size());
  std::vector<Eigen::Vector3d> normals(n, Eigen::Vector3d::Zero());
  if (n < 3) return normals;
  const int k = std::min(std::max(neighbours, 3), n);
  pcl::KdTreeFLANN<pcl::PointXYZ> tree;
  tree.setInputCloud(cloud.makeShared());
  std::vector<std::vector<int>> near(n);
  std::vector<float> squared;
  for (int i = 0; i < n; ++i) {
    tree.nearestKSearch(cloud[i], k, near[i], squared);
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (int j : near[i]) mean += cloud[j].getVector3fMap().cast<double>();
    mean /= near[i].size();
    Eigen::Matrix3d spread = Eigen::Matrix3d::Zero();
    for (int j : near[i]) {
      const Eigen::Vector3d d = cloud[j].getVector3fMap().cast<double>() - mean;
      spread += d * d.transpose();
    }
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(spread);
    // A plane needs two directions of spread: points on a line (or one point) have no normal.
    if (eigen.eigenvalues()[1] > 1e-6 * eigen.eigenvalues()[2]) normals[i] = eigen.eigenvectors().col(0);
  }
  if (viewpoint) {
    for (int i = 0; i < n; ++i)
      if (normals[i].dot(*viewpoint - cloud[i].getVector3fMap().cast<double>()) < 0) normals[i] = -normals[i];
    return normals;
  }
  // Breadth first over the neighbour graph: each point is turned to agree with the one it was
  // reached from, the most parallel neighbours first (they are the surest).
  std::vector<char> done(n, 0);
  for (int seed = 0; seed < n; ++seed) {
    if (done[seed] || normals[seed].isZero(0.0)) continue;
    std::priority_queue<std::pair<double, std::pair<int, int>>> next;  // (|cos|, (to, from))
    done[seed] = 1;
    for (int j : near[seed]) next.push({std::abs(normals[seed].dot(normals[j])), {j, seed}});
    while (!next.empty()) {
      const auto [to, from] = next.top().second;
      next.pop();
      if (done[to] || normals[to].isZero(0.0)) continue;
      done[to] = 1;
      if (normals[to].dot(normals[from]) < 0) normals[to] = -normals[to];
      for (int j : near[to])
        if (!done[j]) next.push({std::abs(normals[to].dot(normals[j])), {j, to}});
    }
  }
  return normals;
}

}  // namespace liver_sim
