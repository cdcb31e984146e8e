// The cloud's voxel grid against PCL's VoxelGrid.
#include <gtest/gtest.h>

#include <cmath>
#include <pcl/filters/voxel_grid.h>

#include <random>

#include "liver_sim/registration/registration.h"
#include "scenarios.h"
#include "regions.h"

namespace liver_sim {
namespace {

// The voxel grid against PCL's VoxelGrid: the same centroids in the same order. Points lie
// within 0.4 voxel of the voxels' centres on both sides of every axis' zero, and in the voxels
// the box's faces cut, so that no rounding puts a point in another voxel. Killed by voxel
// indices truncated instead of floored (the voxels on either side of zero merge), by the y and
// z strides swapped in the key (the order changes) and by a row one voxel short (the last
// voxel of a row merges with the next row's first) (all tried); the crop and the finite count
// alongside.
TEST(PrepareCloud, VoxelCentroidsAreThoseOfPclVoxelGrid) {
  const double voxel = 5e-3;
  std::mt19937 rng(3);
  std::uniform_int_distribution<int> cell(-14, 13);
  std::uniform_real_distribution<double> offset(-0.4, 0.4);
  pcl::PointCloud<pcl::PointXYZ> cloud, inside;
  for (int i = 0; i < 100000; ++i) {
    const pcl::PointXYZ q(voxel * (cell(rng) + 0.5 + offset(rng)), voxel * (cell(rng) + 0.5 + offset(rng)),
                          voxel * (cell(rng) + 0.5 + offset(rng)));
    cloud.push_back(q);
    inside.push_back(q);
    if (i % 100 == 0) cloud.push_back(pcl::PointXYZ(std::nanf(""), 0, 0));
    if (i % 100 == 1) cloud.push_back(pcl::PointXYZ(0, 0, 0.1f));  // beyond the box
  }
  // The box ends half a voxel into cells -15 and 14 along each axis; points in those too.
  for (const float edge : {static_cast<float>(-voxel * 14.3), static_cast<float>(voxel * 14.2)})
    for (int j = -14; j < 14; ++j)
      for (int k = -14; k < 14; ++k) {
        const float a = static_cast<float>(voxel * (j + 0.5)), b = static_cast<float>(voxel * (k + 0.5));
        for (const pcl::PointXYZ& q : {pcl::PointXYZ(edge, a, b), pcl::PointXYZ(a, edge, b), pcl::PointXYZ(a, b, edge)}) {
          cloud.push_back(q);
          inside.push_back(q);
        }
      }
  const Eigen::AlignedBox3d box(Eigen::Vector3d::Constant(-0.0725), Eigen::Vector3d::Constant(0.0725));
  pcl::PointCloud<pcl::PointXYZ> prepared, reference;
  const int finite = prepare_cloud(cloud, Eigen::Isometry3d::Identity(), box, voxel, 1000000, prepared);
  EXPECT_EQ(finite, static_cast<int>(inside.size()) + 1000);  // the points beyond the box
  pcl::VoxelGrid<pcl::PointXYZ> grid;
  grid.setInputCloud(inside.makeShared());
  grid.setLeafSize(voxel, voxel, voxel);
  grid.filter(reference);
  ASSERT_EQ(prepared.size(), reference.size());
  ASSERT_GT(reference.size(), 15000u);  // most of the 28^3 voxels hold points
  for (size_t i = 0; i < reference.size(); ++i)
    ASSERT_LT((prepared[i].getVector3fMap() - reference[i].getVector3fMap()).norm(), 1e-7) << "centroid " << i;
  // A voxel too fine for the box (14.5 million along each axis) is refused, naming the bound.
  EXPECT_TRUE(voxel_grid_error(voxel, box).empty());
  EXPECT_NE(voxel_grid_error(1e-8, box).find("1048576"), std::string::npos) << voxel_grid_error(1e-8, box);
  EXPECT_THROW(prepare_cloud(cloud, Eigen::Isometry3d::Identity(), box, 1e-8, 1000000, prepared), std::invalid_argument);
  // So is a subnormal voxel over a box on one side of 0, whose cell indices overflow to
  // infinity (inf - inf: NaN cells; the grid's hash then never found a free slot). Killed by
  // the bound tested as "any cells above it" (tried: NaN passes it).
  const Eigen::AlignedBox3d positive(Eigen::Vector3d::Constant(0.1), Eigen::Vector3d::Constant(0.3));
  EXPECT_FALSE(voxel_grid_error(1e-310, positive).empty());
  EXPECT_THROW(prepare_cloud(cloud, Eigen::Isometry3d::Identity(), positive, 1e-310, 1000000, prepared), std::invalid_argument);
}

}  // namespace
}  // namespace liver_sim
