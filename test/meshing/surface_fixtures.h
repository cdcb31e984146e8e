// What the meshing tests share: surfaces with known shapes (a box, the package's phantom) and
// the messages of refused files and surfaces.
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <filesystem>
#include <set>
#include <string>
#include <vector>

#include "liver_sim/io/mesh_io.h"
#include "liver_sim/io/surface_io.h"
#include "liver_sim/meshing/anatomy.h"
#include "liver_sim/meshing/surface_repair.h"
#include "liver_sim/scene/scene.h"

namespace liver_sim {
namespace meshing_test {

namespace fs = std::filesystem;

inline fs::path temp_dir() {
  const fs::path d = fs::temp_directory_path() / ("liver_sim_meshing_test_" + std::to_string(::getpid()));
  fs::create_directories(d);
  return d;
}

// A closed, outward surface: the boundary of a box mesh, moved off the origin and given
// coordinates with many digits (mm, like a segmentation).
inline SurfaceMesh box_surface(const Eigen::Vector3d& size = {100.3, 80.7, 60.1}, const Eigen::Vector3d& at = {-12.345678901, 3.25, 7.1}) {
  const TetMesh m = make_box_mesh(size, {4, 3, 2});
  SurfaceMesh s{m.V, boundary_triangles(m.T)};
  s.V.rowwise() += at.transpose();
  return repair_surface(s, "box");  // drops the box's interior nodes
}

// Each triangle as its three corner positions, rotated to start at its smallest corner, as a set:
// two surfaces with equal sets have the same triangles with the same orientation.
inline std::set<std::vector<double>> oriented_triangles(const SurfaceMesh& s) {
  std::set<std::vector<double>> out;
  for (Eigen::Index t = 0; t < s.F.rows(); ++t) {
    std::vector<std::vector<double>> corners;
    for (int k = 0; k < 3; ++k) {
      std::vector<double> p;
      for (int c = 0; c < 3; ++c) p.push_back(s.V(s.F(t, k), c));
      corners.push_back(p);
    }
    const int first = static_cast<int>(std::min_element(corners.begin(), corners.end()) - corners.begin());
    std::vector<double> key;
    for (int k = 0; k < 3; ++k) key.insert(key.end(), corners[(first + k) % 3].begin(), corners[(first + k) % 3].end());
    out.insert(key);
  }
  return out;
}

inline std::string repair_error(const SurfaceMesh& s, const SurfaceRepairOptions& o = {}) {
  try {
    repair_surface(s, "liver.stl", o);
  } catch (const MeshError& e) {
    return e.what();
  }
  ADD_FAILURE() << "the surface was accepted";
  return "";
}

inline std::string read_error(const std::string& bytes, SurfaceFormat format) {
  try {
    read_surface(bytes, format, "liver.stl");
  } catch (const MeshError& e) {
    return e.what();
  }
  ADD_FAILURE() << "the file was accepted";
  return "";
}

// The package's phantom (23 cm) as its mesh's boundary: closed, outward, metres, LPS.
inline SurfaceMesh phantom_surface() {
  const TetMesh m = read_mesh(std::string(LIVER_SIM_SOURCE_DIR) + "/config/phantom/liver_phantom.msh");
  return repair_surface({m.V, boundary_triangles(m.T)}, "phantom boundary");
}

// A model of `s` as make_model writes its scene: the reference parameters with the capsule,
// attached at the bare area, under gravity supine; a static step solved to 1e-8.
inline Scene gravity_scene(const SurfaceMesh& s) {
  Scene scene;
  scene.parenchyma.young_modulus = 30000;
  scene.capsule.enabled = true;
  scene.capsule.young_modulus = 3e6;
  scene.capsule.thickness = 93e-6;
  scene.fixed.push_back(bare_area(s));
  scene.loads.push_back(LoadOptions::gravity({0, 9.81, 0}));
  scene.solver.max_iterations = 50;
  scene.solver.tolerance = 1e-8;
  return scene;
}

}  // namespace meshing_test
}  // namespace liver_sim
