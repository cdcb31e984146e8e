// Vessels embedded in the tissue: they stiffen it, a vanishing modulus changes nothing, the
// node order does not matter, rigid rotations give no force.
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

std::string write_file(const std::string& name, const std::string& text) {
  const std::string path = ::testing::TempDir() + name;
  std::ofstream(path) << text;
  return path;
}

// A line of `segments` beams along x through the block's axis, nodes in the given order.
std::string vessel_line_yaml(int segments, bool reversed) {
  std::ostringstream y;
  y << "nodes:\n";
  for (int k = 0; k <= segments; ++k) {
    const int i = reversed ? segments - k : k;
    y << "  - [" << 0.002 + 0.036 * i / segments << ", 0.005, 0.005, 0.0015, 0.0005]\n";
  }
  y << "segments:\n";
  for (int k = 0; k < segments; ++k) {
    const int a = reversed ? segments - k : k, b = reversed ? segments - k - 1 : k + 1;
    y << "  - [" << b << ", " << a << "]\n";  // also flips each segment's direction
  }
  return y.str();
}

// A 40 x 10 x 10 mm block of parenchyma clamped at x = 0 with a downward force on its far end.
Scene cantilever_block(const std::string& vessel_file, double vessel_modulus) {
  Scene s;
  s.parenchyma.young_modulus = 3000;
  s.parenchyma.poisson_ratio = 0.45;
  s.solver.tolerance = 1e-10;
  s.fixed.push_back(box({-1, -1, -1}, {0, 1, 1}));
  LoadOptions load;
  load.kind = LoadOptions::Kind::Force;
  load.vector = Eigen::Vector3d(0, 0, -2e-4);  // N
  load.region = box({0.04, -1, -1}, {1, 1, 1});
  s.loads.push_back(load);
  s.probes.push_back({"tip", {0.04, 0.005, 0.005}});
  if (!vessel_file.empty()) {
    VesselOptions v;
    v.name = "line";
    v.file = vessel_file;
    v.young_modulus = vessel_modulus;
    s.vessels.push_back(v);
  }
  return s;
}

TetMesh block_mesh() { return make_box_mesh({0.04, 0.01, 0.01}, {12, 3, 3}); }

Eigen::Vector3d tip_after_step(const Scene& s) {
  LiverModel m(block_mesh(), s);
  const StepResult r = m.step();
  EXPECT_TRUE(r.converged()) << r.message;
  return m.probe_displacement(0);
}

TEST(EmbeddedVessel, StiffVesselReducesDeflection) {
  const std::string file = write_file("line.yaml", vessel_line_yaml(12, false));
  const double without = tip_after_step(cantilever_block("", 0)).z();
  const double with = tip_after_step(cantilever_block(file, 0.62e6)).z();
  ASSERT_LT(without, 0);
  // The vessel's bending stiffness E I is about 0.8 of the block's: expect a clear reduction.
  EXPECT_LT(std::abs(with), 0.8 * std::abs(without)) << "with " << with << " without " << without;
  EXPECT_GT(std::abs(with), 0.2 * std::abs(without));
}

TEST(EmbeddedVessel, VanishingModulusLeavesResultUnchanged) {
  const std::string file = write_file("line.yaml", vessel_line_yaml(12, false));
  const Eigen::Vector3d u0 = tip_after_step(cantilever_block("", 0));
  const double d1 = (tip_after_step(cantilever_block(file, 62.0)) - u0).norm();
  const double d2 = (tip_after_step(cantilever_block(file, 0.62)) - u0).norm();
  EXPECT_GT(d1, 0);
  // First order in the modulus: 100x smaller modulus, about 100x smaller change.
  EXPECT_LT(d2, 0.02 * d1) << d1 << " " << d2;
  EXPECT_LT(d2, 1e-5 * u0.norm());
}

TEST(EmbeddedVessel, ResultDoesNotDependOnNodeOrder) {
  const Eigen::Vector3d a = tip_after_step(cantilever_block(write_file("fwd.yaml", vessel_line_yaml(12, false)), 0.62e6));
  const Eigen::Vector3d b = tip_after_step(cantilever_block(write_file("rev.yaml", vessel_line_yaml(12, true)), 0.62e6));
  EXPECT_LE((a - b).norm(), 1e-7 * a.norm()) << a.transpose() << " vs " << b.transpose();
}

TEST(EmbeddedVessel, NodesOutsideTheMeshAreSnappedOrNamed) {
  const std::string near = write_file(
      "near.yaml", "nodes: [[0.01, 0.005, 0.0103, 0.001, 0.0002], [0.02, 0.005, 0.005, 0.001, 0.0002]]\nsegments: [[0, 1]]\n");
  EXPECT_NO_THROW(LiverModel(block_mesh(), cantilever_block(near, 0.62e6)));  // 0.3 mm out: snapped
  const std::string far = write_file(
      "far.yaml", "nodes: [[0.01, 0.005, 0.005, 0.001, 0.0002], [0.02, 0.005, 0.015, 0.001, 0.0002]]\nsegments: [[0, 1]]\n");
  try {
    LiverModel m(block_mesh(), cantilever_block(far, 0.62e6));
    ADD_FAILURE() << "a node 5 mm outside was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("vessels.line: node 1"), std::string::npos) << e.what();
  }
  const std::string cyclic = write_file(
      "cyclic.yaml", "nodes: [[0.01,0.005,0.005,0.001,0.0002],[0.02,0.005,0.005,0.001,0.0002],[0.02,0.006,0.005,0.001,0.0002]]\n"
                     "segments: [[0,1],[1,2],[2,0]]\n");
  EXPECT_THROW(LiverModel(block_mesh(), cantilever_block(cyclic, 0.62e6)), std::invalid_argument);
}

// Rigid rotation of the whole vascularised block: the vessel rotations follow the tissue's, so
// no force.
TEST(EmbeddedVessel, RigidRotationOfTissueAndVesselGivesZeroForce) {
  const std::string file = write_file("line.yaml", vessel_line_yaml(12, false));
  LiverModel m(block_mesh(), cantilever_block(file, 0.62e6));
  const Eigen::Matrix3d Q = rotation_exp(Eigen::Vector3d(0.4, -0.8, 1.2));
  Eigen::VectorXd x = m.positions();
  for (int i = 0; i < x.size(); i += 3) x.segment<3>(i) = Q * x.segment<3>(i) + Eigen::Vector3d(0.01, 0.02, -0.03);
  Eigen::VectorXd f;
  m.mechanics().internal_forces(x, f);
  // Scale: the force that a 1% strain of the block makes, E A 0.01.
  EXPECT_LE(f.cwiseAbs().maxCoeff(), 1e-9 * 3000 * 1e-4 * 0.01);
}

// The rotation of a tetrahedron (polar decomposition) and its derivative, against differences.
TEST(EmbeddedVessel, PolarRotationDerivativeMatchesDifferences) {
  Eigen::Matrix3d Dm;
  Dm << 0.01, 0.002, 0.001, 0.0, 0.009, 0.003, 0.001, 0.0, 0.011;
  const Eigen::Matrix3d Dm_inv = Dm.inverse();
  Eigen::Matrix<double, 12, 1> x;
  x << 0, 0, 0, 0.0105, 0.001, -0.002, 0.003, 0.0085, 0.001, 0.0, 0.004, 0.0102;
  auto F_of = [&](const Eigen::Matrix<double, 12, 1>& y) {
    Eigen::Matrix3d Ds;
    for (int k = 0; k < 3; ++k) Ds.col(k) = y.segment<3>(3 * k + 3) - y.head<3>();
    return Eigen::Matrix3d(Ds * Dm_inv);
  };
  const Eigen::Matrix3d R = polar_rotation(F_of(x));
  const Eigen::Matrix<double, 3, 12> G = polar_rotation_derivative(R, F_of(x), Dm_inv);
  Eigen::Matrix<double, 12, 1> v;
  v << 0.3, -0.2, 0.5, 0.1, 0.7, -0.4, -0.6, 0.2, 0.3, 0.25, -0.15, 0.05;
  const double h = 1e-8;
  const Eigen::Vector3d dtheta =
      (rotation_log(polar_rotation(F_of(x + h * v)) * R.transpose()) - rotation_log(polar_rotation(F_of(x - h * v)) * R.transpose())) / (2 * h);
  EXPECT_LE((dtheta - G * v).norm(), 1e-6 * dtheta.norm());
}

// The scenes with vessel trees: the phantom (the node's default) and the external SOFA liver.
// Each converges under gravity with and without its vessels, and the vessels stiffen the organ.
struct VesselScene {
  const char* file;
  const char* probe;  // the displacement compared; empty: the largest node displacement
};
class VascularisedLiver : public ::testing::TestWithParam<VesselScene> {};

TEST_P(VascularisedLiver, VesselsStiffenTheOrgan) {
  Scene s = load_scene(std::string(LIVER_SIM_SOURCE_DIR) + "/config/scenes/" + GetParam().file);
  auto sag = [&](const Scene& scene) {
    LiverModel m(load_scene_mesh(scene), scene);
    const StepResult r = m.step();
    EXPECT_TRUE(r.converged()) << r.message;
    EXPECT_TRUE(m.positions().allFinite());
    if (std::string(GetParam().probe).empty()) return m.max_displacement();
    for (int p = 0; p < m.num_probes(); ++p)
      if (m.probe_name(p) == GetParam().probe) return m.probe_displacement(p).norm();
    ADD_FAILURE() << "no probe " << GetParam().probe;
    return 0.0;
  };
  ASSERT_FALSE(s.vessels.empty());
  const double with = sag(s);
  s.vessels.clear();
  const double without = sag(s);
  EXPECT_GT(with, 0);
  EXPECT_LT(with, 0.99 * without) << "with " << with << " m, without " << without << " m";
}

INSTANTIATE_TEST_SUITE_P(Scenes, VascularisedLiver,
                         ::testing::Values(VesselScene{"liver_phantom.yaml", "tumour_centre"},
                                           VesselScene{"sofa_liver.yaml", ""}),
                         [](const auto& info) {
                           const std::string f = info.param.file;
                           return f.substr(0, f.find('.'));
                         });

}  // namespace
}  // namespace liver_sim
