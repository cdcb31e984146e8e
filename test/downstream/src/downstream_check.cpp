// Built against an installed liver_sim with only what its catkin_package exports: the model's
// header (Eigen), CHOLMOD's wrapper and the tracking session's (PCL) compile, the libraries link,
// and the model of the scene given steps to its equilibrium.
//   downstream_check SCENE.yaml   exit 0 when the step converged
#include <iostream>

#include "liver_sim/io/scene_files.h"
#include "liver_sim/linalg/cholmod_solver.h"
#include "liver_sim/session/tracking_session.h"
#include "liver_sim/simulation/liver_model.h"

int main(int argc, char** argv) {
  if (argc != 2) {
    std::cerr << "usage: downstream_check SCENE.yaml\n";
    return 2;
  }
  const liver_sim::Scene scene = liver_sim::load_scene(argv[1]);
  liver_sim::LiverModel model(liver_sim::load_scene_mesh(scene), scene);
  const liver_sim::StepResult r = model.step();
  std::cout << "downstream_check: " << model.mesh().T.rows() << " tetrahedra, step " << (r.converged() ? "converged" : "not converged")
            << ", max displacement " << model.max_displacement() << " m\n";
  return r.converged() ? 0 : 1;
}
