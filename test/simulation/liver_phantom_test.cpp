// The vascularised liver phantom: its size, vessels and targets, its factor, its real-time frames.
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

TEST(LiverPhantom, HasTheStatedSizeVesselsAndTargets) {
  const Scene s = load_scene(std::string(LIVER_SIM_SOURCE_DIR) + "/config/scenes/liver_phantom.yaml");
  const LiverModel m(load_scene_mesh(s), s);
  EXPECT_GE(m.mesh().T.rows(), 10000);
  EXPECT_EQ(m.num_beams(), 68 + 84);
  EXPECT_EQ(m.vessel_name(m.beam_vessel(0)), "portal");
  EXPECT_EQ(m.vessel_name(m.beam_vessel(m.num_beams() - 1)), "hepatic");
  EXPECT_EQ(m.num_probes(), 7);
  const Eigen::Vector3d extent = m.mesh().V.colwise().maxCoeff() - m.mesh().V.colwise().minCoeff();
  EXPECT_NEAR(extent.x(), 0.235, 0.005);  // metres: an adult liver's size
  EXPECT_NEAR(extent.z(), 0.095, 0.005);
}

// The analysis keeps the ordering with less fill: on the phantom (tetrahedra, membranes and the
// beams' couplings) METIS leaves 13% fewer nonzeros in L than the AMD ordering that CHOLMOD's
// default analysis keeps.
TEST(LiverPhantom, FactorKeepsTheOrderingWithLessFill) {
  const Scene s = load_scene(std::string(LIVER_SIM_SOURCE_DIR) + "/config/scenes/liver_phantom.yaml");
  LiverModel m(load_scene_mesh(s), s);
  const SparsePattern& pattern = m.mechanics().pattern();
  cholmod_common common;
  cholmod_start(&common);
  cholmod_sparse A{};
  A.nrow = A.ncol = static_cast<size_t>(pattern.rows());
  A.nzmax = pattern.row_index().size();
  A.p = const_cast<int*>(pattern.column_start().data());
  A.i = const_cast<int*>(pattern.row_index().data());
  A.stype = 1;
  A.itype = CHOLMOD_INT;
  A.xtype = CHOLMOD_PATTERN;
  A.dtype = CHOLMOD_DOUBLE;
  A.sorted = A.packed = 1;
  cholmod_factor* L = cholmod_analyze(&A, &common);
  ASSERT_NE(L, nullptr);
  const double default_fill = common.lnz;
  cholmod_free_factor(&L, &common);
  cholmod_finish(&common);
  EXPECT_LT(m.stepper().linear_solver().factor_nonzeros(), 0.95 * default_fill) << "default " << default_fill;
}

// Real-time frames on the phantom (10 ms, one modified-Newton iteration each, breathing
// gravity) against the converged dynamics. With the scene's constant-acceleration predictor they
// stay within 1% of the largest motion (0.5% measured; the constant-velocity one lags by 4% after
// 60 frames). When the old factor no longer gives descent the iteration is redone on a fresh one;
// spending it instead stalled frame 19 and rolled it back.
TEST(LiverPhantom, RealTimeFramesTrackTheConvergedDynamics) {
  const std::string path = std::string(LIVER_SIM_SOURCE_DIR) + "/config/scenes/liver_phantom.yaml";
  const Scene s0 = load_scene(path, {"solver.strategy=newton_krylov", "solver.tolerance=1e-10", "solver.max_iterations=100"});
  LiverModel equilibrium(load_scene_mesh(s0), s0);
  ASSERT_TRUE(equilibrium.step().converged());
  std::vector<Eigen::VectorXd> motion[2];
  int factorizations = 0;
  for (int run = 0; run < 2; ++run) {
    const Scene s = load_scene(path, {"solver.mode=dynamic", "solver.dt=0.01",
                                      run == 0 ? "solver.strategy=newton_krylov" : "solver.strategy=modified_newton",
                                      run == 0 ? "solver.max_iterations=50" : "solver.max_iterations=1",
                                      run == 0 ? "solver.tolerance=1e-10" : "solver.tolerance=1e-300"});
    ASSERT_EQ(s.solver.predictor, SolverOptions::Predictor::ConstantAcceleration);
    LiverModel m(load_scene_mesh(s), s);
    m.set_positions(equilibrium.positions());
    for (int k = 1; k <= 60; ++k) {
      m.set_load_scale(1 + 0.5 * std::sin(2 * M_PI * k * s.solver.dt));
      const StepResult r = m.step();
      ASSERT_NE(r.status, StepResult::Status::Diverged) << "run " << run << " frame " << k << ": " << r.message;
      if (run == 1) factorizations += r.factorizations;
      motion[run].push_back(m.positions() - equilibrium.positions());
    }
  }
  double peak = 0, error = 0;
  for (size_t k = 0; k < motion[0].size(); ++k) {
    peak = std::max(peak, motion[0][k].cwiseAbs().maxCoeff());
    error = std::max(error, (motion[1][k] - motion[0][k]).cwiseAbs().maxCoeff());
  }
  ASSERT_GT(peak, 1e-3);  // m: the breathing load moves the liver by millimetres
  EXPECT_LE(error, 0.01 * peak);
  EXPECT_GE(factorizations, 2);  // the first, and at least one refresh
}

}  // namespace
}  // namespace liver_sim
