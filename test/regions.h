// Shared by the core tests: region shorthands.
#pragma once

#include "liver_sim/geometry/region.h"

namespace liver_sim {

inline Region box(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
  Region r;
  r.kind = Region::Kind::Box;
  r.min = lo;
  r.max = hi;
  return r;
}

}  // namespace liver_sim
