#include "liver_sim/stepper/newton_matrix.h"

#include <chrono>

#include "liver_sim/stepper/step_result.h"
#include "wall_time.h"

namespace liver_sim {

NewtonMatrix::NewtonMatrix(MechanicalModel& mechanics, const SolverOptions& solver)
    : mechanics_(mechanics), solver_(solver), values_(mechanics.pattern().nonzeros(), 0.0) {}

void NewtonMatrix::assemble(StepTiming& timing) {
  const auto t0 = std::chrono::steady_clock::now();
  double k_scale = 1.0, m_scale = 0.0;
  if (solver_.mode == SolverOptions::Mode::Dynamic) {
    const double dt = solver_.dt;
    k_scale = 1.0 + solver_.rayleigh_stiffness / dt;
    m_scale = 1.0 / (dt * dt) + solver_.rayleigh_mass / dt;
  }
  mechanics_.assemble(k_scale, m_scale, values_);
  timing.assembly_ms += ms_since(t0);
}

}  // namespace liver_sim
