// Mesh files: every writer round-trips, malformed files are named with their problem, the SOFA
// livers load as closed valid volumes.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>

#include "liver_sim/geometry/mesh.h"
#include "liver_sim/io/mesh_io.h"
#include "geometry/mesh_checks.h"

namespace liver_sim {
namespace {

namespace fs = std::filesystem;

fs::path temp_dir() {
  const fs::path d = fs::temp_directory_path() / ("liver_sim_test_mesh_" + std::to_string(::getpid()));
  fs::create_directories(d);
  return d;
}

std::string write_file(const std::string& name, const std::string& text) {
  const fs::path p = temp_dir() / name;
  std::ofstream(p) << text;
  return p.string();
}

// Message of the MeshError thrown by read_mesh, or "" when it loads.
std::string load_error(const std::string& path) {
  try {
    read_mesh(path);
  } catch (const MeshError& e) {
    return e.what();
  }
  return "";
}

TEST(MeshIO, RoundTripsThroughEveryWriter) {
  const TetMesh m = make_box_mesh({0.0152, 0.0113, 0.0097}, {3, 2, 2});
  using Writer = void (*)(const std::string&, const TetMesh&);
  const std::vector<std::pair<std::string, Writer>> writers = {
      {"m22.msh", write_gmsh22}, {"m41.msh", write_gmsh41}, {"m.vtk", write_vtk}};
  for (const auto& [name, write] : writers) {
    const std::string path = (temp_dir() / name).string();
    write(path, m);
    const TetMesh r = read_mesh(path);
    EXPECT_EQ(r.T, m.T) << name;
    EXPECT_EQ(r.V, m.V) << name;
    const TetMesh scaled = read_mesh(path, 0.001);
    EXPECT_LE((scaled.V - 0.001 * m.V).cwiseAbs().maxCoeff(), 1e-18) << name;
  }
}

TEST(MeshIO, IgnoresOtherElementsAndUnusedNodes) {
  const std::string path = write_file("mixed.msh",
                                      "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n"
                                      "$PhysicalNames\n1\n3 1 \"liver\"\n$EndPhysicalNames\n"
                                      "$Nodes\n6\n10 0 0 0\n20 1 0 0\n30 0 1 0\n40 0 0 1\n50 5 5 5\n60 1 1 1\n$EndNodes\n"
                                      "$Elements\n4\n1 15 2 0 0 50\n2 2 2 0 0 10 20 30\n"
                                      "3 4 2 1 1 10 20 30 40\n4 1 2 0 0 10 60\n$EndElements\n");
  const TetMesh m = read_mesh(path);
  EXPECT_EQ(m.T.rows(), 1);
  EXPECT_EQ(m.V.rows(), 4);

  const std::string vtk = write_file("mixed.vtk",
                                     "# vtk DataFile Version 3.0\nmixed\nASCII\nDATASET UNSTRUCTURED_GRID\n"
                                     "POINTS 5 double\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n7 7 7\n"
                                     "CELLS 3 11\n3 0 1 2\n4 0 1 2 3\n1 4\nCELL_TYPES 3\n5\n10\n1\n"
                                     "POINT_DATA 5\nSCALARS t double 1\nLOOKUP_TABLE default\n0\n0\n0\n0\n0\n");
  const TetMesh v = read_mesh(vtk);
  EXPECT_EQ(v.T.rows(), 1);
  EXPECT_EQ(v.V.rows(), 4);
}

TEST(MeshIO, ReorientsAFileWhoseTetrahedraAreAllNegative) {
  TetMesh m = make_box_mesh({1, 1, 1}, {2, 1, 1});
  m.T.col(0).swap(m.T.col(1));
  const std::string path = (temp_dir() / "negative.msh").string();
  write_gmsh22(path, m);
  const TetMesh r = read_mesh(path);
  EXPECT_TRUE(check_mesh(r).ok());
}

TEST(MeshIO, RejectsMalformedFilesNamingFileAndProblem) {
  const std::string tet22 = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n$EndNodes\n";
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"", "empty"},
      {"hello world\n", "unknown format"},
      {"$NOD\n3\n1 0 0 0\n2 1 0 0\n", "end of file"},
      {tet22 + "$Elements\n1\n1 4 2 1 1 1 2 3 9\n$EndElements\n", "undefined node"},
      {"$NOD\n4\n1 0 0 0\n2 1 x 0\n3 0 1 0\n4 0 0 1\n$ENDNOD\n$ELM\n1\n1 4 1 1 4 1 2 3 4\n$ENDELM\n", "'x'"},
      {"$NOD\n4\n1 0 0 0\n2 1 nan 0\n3 0 1 0\n4 0 0 1\n$ENDNOD\n$ELM\n1\n1 4 1 1 4 1 2 3 4\n$ENDELM\n", "not finite"},
      {tet22 + "$Elements\n1\n1 2 2 1 1 1 2 3\n$EndElements\n", "no tetrahedra"},
      {"$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n1 0 0 0\n2 1 0 0\n3 2 0 0\n4 3 0 0\n$EndNodes\n"
       "$Elements\n1\n1 4 2 1 1 1 2 3 4\n$EndElements\n", "degenerate"},
      {"$MeshFormat\n2.2 1 8\n$EndMeshFormat\n", "binary"},
      {"# vtk DataFile Version 3.0\nx\nBINARY\nDATASET UNSTRUCTURED_GRID\n", "ASCII"},
      {"# vtk DataFile Version 3.0\nx\nASCII\nDATASET POLYDATA\n", "UNSTRUCTURED_GRID"},
      {"$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 4 1 4\n3 1 0 4\n1\n2\n3\n4\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n"
       "$EndNodes\n$Elements\n1 1 1 1\n3 1 99 1\n1 1 2 3 4\n$EndElements\n", "unknown element type"},
  };
  for (size_t i = 0; i < cases.size(); ++i) {
    const std::string name = "bad" + std::to_string(i) + ".msh";
    const std::string message = load_error(write_file(name, cases[i].first));
    EXPECT_NE(message.find(name), std::string::npos) << "case " << i << ": " << message;
    EXPECT_NE(message.find(cases[i].second), std::string::npos) << "case " << i << ": " << message;
  }
  EXPECT_NE(load_error((temp_dir() / "missing.msh").string()).find("cannot open"), std::string::npos);
}

TEST(MeshIO, MixedOrientationIsRejectedWithTheElementIndex) {
  TetMesh m = make_box_mesh({1, 1, 1}, {1, 1, 1});
  std::swap(m.T(1, 0), m.T(1, 1));
  const std::string path = (temp_dir() / "mixed_orientation.msh").string();
  write_gmsh22(path, m);
  const std::string message = load_error(path);
  EXPECT_NE(message.find("1 inverted tetrahedra (of 5): 1"), std::string::npos) << message;
}

// The two SOFA liver meshes: legacy Gmsh 1.0, non-contiguous node ids, mixed element types.
struct SofaMesh {
  const char* file;
  int tetrahedra;
};
class SofaLiverMesh : public ::testing::TestWithParam<SofaMesh> {};

TEST_P(SofaLiverMesh, LoadsAsAClosedValidVolume) {
  const std::string path = std::string(LIVER_SIM_SOURCE_DIR) + "/config/sofa_liver/" + GetParam().file;
  const TetMesh m = read_mesh(path, 0.01);
  EXPECT_EQ(m.T.rows(), GetParam().tetrahedra);
  EXPECT_TRUE(check_mesh(m).ok());
  expect_closed_outward_boundary(m);
}

INSTANTIATE_TEST_SUITE_P(Both, SofaLiverMesh,
                         ::testing::Values(SofaMesh{"liver.msh", 596}, SofaMesh{"liver2.msh", 1493}),
                         [](const auto& info) {
                           const std::string f = info.param.file;
                           return f.substr(0, f.find('.'));
                         });

}  // namespace
}  // namespace liver_sim
