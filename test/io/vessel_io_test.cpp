// Vessel trees read from YAML and VTK polylines; bad trees name the node or segment.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <cmath>
#include <fstream>
#include <sstream>

#include "liver_sim/model/corotational_beam.h"
#include "liver_sim/simulation/liver_model.h"
#include "regions.h"
#include "liver_sim/geometry/vessel_tree.h"
#include "liver_sim/io/vessel_io.h"

namespace liver_sim {
namespace {

std::string expect_vessel_error(const std::string& yaml) {
  try {
    read_vessel_yaml(yaml, "tree.yaml");
  } catch (const VesselError& e) {
    return e.what();
  }
  ADD_FAILURE() << "no error for:\n" << yaml;
  return "";
}

TEST(VesselTree, ReadsYamlWithScale) {
  const VesselTree t = read_vessel_yaml(
      "nodes:\n  - [0, 0, 0, 3, 1]\n  - [10, 0, 0, 2, 0.5]\n  - [10, 10, 0, 2, 2]\nsegments: [[0, 1], [1, 2]]\n",
      "tree.yaml", 1e-3);
  ASSERT_EQ(t.points.rows(), 3);
  ASSERT_EQ(t.segments.rows(), 2);
  EXPECT_DOUBLE_EQ(t.points(1, 0), 0.01);
  EXPECT_DOUBLE_EQ(t.radius[0], 0.003);
  EXPECT_DOUBLE_EQ(t.wall_thickness[1], 0.0005);
  EXPECT_EQ(t.segments(1, 1), 2);
}

TEST(VesselTree, ReadsVtkPolylines) {
  std::istringstream in(
      "# vtk DataFile Version 3.0\nportal\nASCII\nDATASET POLYDATA\nPOINTS 4 double\n"
      "0 0 0  1 0 0  2 0 0  1 1 0\nLINES 2 7\n3 0 1 2\n2 1 3\nPOINT_DATA 4\n"
      "SCALARS radius double 1\nLOOKUP_TABLE default\n0.3 0.3 0.2 0.2\n"
      "SCALARS wall_thickness double\nLOOKUP_TABLE default\n0.1 0.1 0.05 0.05\n");
  const VesselTree t = read_vessel_vtk(in, "portal.vtk");
  ASSERT_EQ(t.segments.rows(), 3);  // a polyline of 3 points is 2 segments
  EXPECT_EQ(t.segments(1, 0), 1);
  EXPECT_EQ(t.segments(1, 1), 2);
  EXPECT_EQ(t.segments(2, 1), 3);
  EXPECT_DOUBLE_EQ(t.wall_thickness[3], 0.05);
}

TEST(VesselTree, BadTreesNameTheNodeOrSegment) {
  const std::string nodes = "nodes: [[0,0,0,1,0.1], [1,0,0,1,0.1], [1,1,0,1,0.1]]\n";
  EXPECT_NE(expect_vessel_error(nodes + "segments: [[0,1],[1,2],[2,0]]").find("segment 2 (2-0): closes a cycle"),
            std::string::npos);
  EXPECT_NE(expect_vessel_error(nodes + "segments: [[0,1],[1,0],[1,2]]").find("segment 1"), std::string::npos);
  EXPECT_NE(expect_vessel_error("nodes: [[0,0,0,1,0.1], [1,0,0,0,0.1]]\nsegments: [[0,1]]").find("node 1: radius"),
            std::string::npos);
  EXPECT_NE(expect_vessel_error("nodes: [[0,0,0,1,0.1], [1,0,0,1,1.5]]\nsegments: [[0,1]]").find("node 1: wall thickness"),
            std::string::npos);
  EXPECT_NE(expect_vessel_error("nodes: [[0,.nan,0,1,0.1], [1,0,0,1,0.1]]\nsegments: [[0,1]]").find("node 0: coordinates"),
            std::string::npos);
  EXPECT_NE(expect_vessel_error(nodes + "segments: [[0,1],[1,3]]").find("segment 1"), std::string::npos);
  EXPECT_NE(expect_vessel_error(nodes + "segments: [[0,1],[1,1]]").find("itself"), std::string::npos);
  EXPECT_NE(expect_vessel_error(nodes + "segments: [[0,1]]").find("node 2: belongs to no segment"), std::string::npos);
  EXPECT_NE(expect_vessel_error("nodes: [[0,0,0,1,0.1], [0,0,0,1,0.1]]\nsegments: [[0,1]]").find("zero length"),
            std::string::npos);
  EXPECT_NE(expect_vessel_error("nodes: [[0,0,0,1,0.1]]\nsegments: []").find("at least 2 nodes"), std::string::npos);
  EXPECT_THROW(read_vessel_tree("/nonexistent/tree.vtk"), VesselError);
}

}  // namespace
}  // namespace liver_sim
