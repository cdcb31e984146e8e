// bench's press-and-sweep: a probe posed as scripts/measure_or.py poses the node's, its depth
// measured from the surface found under it in the scene's static equilibrium (the node's script
// finds it the same way in the node's settled mesh), so that bench presses as deep as the node's
// measurement does.
#pragma once

#include <Eigen/Core>
#include <optional>
#include <string>

#include "liver_sim/scene/options.h"

namespace liver_sim::bench {

// Above the point `above` (x, y), the instrument's lowest point goes between depth_min and
// depth_max below the surface and back once a `period` (a raised cosine from depth_min), while
// it sweeps +-sweep/2 along x once two periods (a sine from the centre); one keyframe every
// 1/rate s for `duration` s. The instrument points down: a shaft rises along +z from its tip.
struct PressSweep {
  InstrumentOptions instrument;  // name, type (probe or shaft), radius, length; no trajectory
  Eigen::Vector2d above = Eigen::Vector2d::Zero();  // m
  double depth_min = 0, depth_max = 0;               // m below the surface, 0 <= min <= max <= 0.05
  double sweep = 0;                                  // m along x, in [0, 0.1]
  double period = 1, rate = 30, duration = 1;        // s (> 0), Hz (in (0, 1000]), s (> 0)
};

// The press of an instruments file whose root is a `press_sweep:` map (nothing when it is
// something else: an instruments list). Throws std::runtime_error naming the file and the key.
std::optional<PressSweep> read_press_sweep(const std::string& path);

// Height (m) of the surface at x, y: the highest crossing of the vertical line through it with
// a boundary triangle of the tetrahedra T at positions x (3 per node). Throws
// std::runtime_error when no triangle lies above the point.
double surface_height(const Eigen::MatrixX4i& T, const Eigen::VectorXd& x, const Eigen::Vector2d& xy);

// The instrument moving along the press, the surface at height `surface` (m).
InstrumentOptions press_sweep_instrument(const PressSweep& p, double surface);

}  // namespace liver_sim::bench
