// A cloud's preparation before it registers, ROS-free: moved into the model frame, cropped,
// downsampled on a voxel grid, with its bounds on size.
#pragma once

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <string>

namespace liver_sim {

// Points an incoming cloud may hold before its preparation: a 5-megapixel structured-light
// camera gives 5e6; the node converts the message and the preparation copies it (without a
// voxel grid) or keeps a sum per voxel, so ten million points cost up to about 0.5 GB and
// several frames.
constexpr uint64_t kMaxCloudPoints = 10000000;
// "" when a cloud of `points` points is within kMaxCloudPoints, else the refusal naming the bound.
std::string cloud_size_error(uint64_t points);

// "" when a voxel grid of `voxel` (m; 0: none) over `box` has at most 2^20 voxels along each
// axis, else the refusal naming the bound.
std::string voxel_grid_error(double voxel, const Eigen::AlignedBox3d& box);

// Cloud preparation, shared by register_cloud and the node's callback: points moved by
// `transform` (into the model frame), the non-finite ones dropped, those outside `box` dropped,
// then a voxel grid of `voxel` (m; 0: none; each voxel's points become their centroid) and an
// even stride down to `max_points`. Returns the number of finite points received. Throws
// std::invalid_argument for a cloud beyond kMaxCloudPoints and for a voxel too fine for `box`
// (voxel_grid_error).
int prepare_cloud(const pcl::PointCloud<pcl::PointXYZ>& in, const Eigen::Isometry3d& transform,
                  const Eigen::AlignedBox3d& box, double voxel, int max_points, pcl::PointCloud<pcl::PointXYZ>& out);

}  // namespace liver_sim
