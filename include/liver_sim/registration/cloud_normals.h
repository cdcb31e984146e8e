// Surface normals of a point cloud, ROS-free: the direction of least spread of each point's
// nearest neighbours (principal component analysis), turned to face the sensor or, without one,
// to agree from neighbour to neighbour over the cloud. The one-shot registration compares them
// with the model's triangle normals so that a point does not correspond to the other side of a
// thin lobe.
#pragma once

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <Eigen/Core>
#include <optional>
#include <vector>

namespace liver_sim {

// Unit normals of `cloud` (one per point; zero where fewer than 3 distinct neighbours), from its
// `neighbours` nearest points (the point included). With a viewpoint each faces it (a sensor sees
// the front of a surface); without, they are turned one after another along the nearest-neighbour
// graph to agree with the neighbour they were reached from, so that each connected piece of
// surface has one side (which one is left to the caller: flip them all to agree with a model).
std::vector<Eigen::Vector3d> estimate_normals(const pcl::PointCloud<pcl::PointXYZ>& cloud, int neighbours,
                                              const std::optional<Eigen::Vector3d>& viewpoint = std::nullopt);

}  // namespace liver_sim
