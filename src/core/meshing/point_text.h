// A point as the meshing's messages name where a defect is: "(x, y, z)" in m, six digits.
#pragma once

#include <Eigen/Core>
#include <sstream>
#include <string>

namespace liver_sim {

inline std::string at(const Eigen::Vector3d& p) {
  std::ostringstream s;
  s.precision(6);
  s << "(" << p[0] << ", " << p[1] << ", " << p[2] << ")";
  return s.str();
}

}  // namespace liver_sim
