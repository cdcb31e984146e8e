// The rigid alignment of clouds to the surface: point-to-plane ICP (PCL).
#include <pcl/registration/icp.h>

#include <algorithm>
#include <cmath>

#include "liver_sim/geometry/node_positions.h"
#include "liver_sim/registration/registration.h"

namespace liver_sim {

void SurfaceRegistration::align_rigidly() {
  // Point-to-plane ICP against the boundary at the current state, sampled on a barycentric grid
  // of about 2 mm with the triangles' normals: distances to the tangent planes are distances to
  // the surface, where distances to the samples would bias the fit by the grid's spacing.
  const Eigen::VectorXd& x = model_.positions();
  const Eigen::MatrixX3i& F = model_.boundary();
  auto surface = pcl::make_shared<pcl::PointCloud<pcl::PointNormal>>();
  for (int t = 0; t < F.rows(); ++t) {
    const Eigen::Vector3d a = node(x, F(t, 0)), b = node(x, F(t, 1)), c = node(x, F(t, 2));
    const Eigen::Vector3d normal = (b - a).cross(c - a).normalized();
    const double longest = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
    const int n = std::max(1, static_cast<int>(std::ceil(longest / 2e-3)));
    for (int i = 0; i <= n; ++i)
      for (int j = 0; i + j <= n; ++j) {
        const Eigen::Vector3d p = a + (b - a) * (static_cast<double>(i) / n) + (c - a) * (static_cast<double>(j) / n);
        pcl::PointNormal q;
        q.getVector3fMap() = p.cast<float>();
        q.getNormalVector3fMap() = normal.cast<float>();
        surface->push_back(q);
      }
  }
  auto source = pcl::make_shared<pcl::PointCloud<pcl::PointNormal>>();
  for (const pcl::PointXYZ& p : *points_) {
    pcl::PointNormal q;
    q.getVector3fMap() = p.getVector3fMap();
    q.getNormalVector3fMap().setZero();
    source->push_back(q);
  }
  pcl::IterativeClosestPointWithNormals<pcl::PointNormal, pcl::PointNormal> icp;
  icp.setInputSource(source);
  icp.setInputTarget(surface);
  icp.setMaxCorrespondenceDistance(5 * options_.max_distance);
  icp.setMaximumIterations(200);
  icp.setTransformationEpsilon(1e-14);
  icp.setEuclideanFitnessEpsilon(0);
  pcl::PointCloud<pcl::PointNormal> moved;
  icp.align(moved);
  if (!icp.hasConverged()) return;  // left unaligned; the next cloud tries again
  const Eigen::Isometry3d step(icp.getFinalTransformation().cast<double>());
  alignment_ = step * alignment_;
  for (size_t i = 0; i < moved.size(); ++i) (*points_)[i].getVector3fMap() = moved[i].getVector3fMap();
  aligned_ = true;
  align_requested_ = false;
}

}  // namespace liver_sim
