// Conversion of the model's deformed surface and vessels into rviz markers.
#pragma once

#include <std_msgs/ColorRGBA.h>
#include <visualization_msgs/Marker.h>

#include "liver_sim/liver_model.h"

namespace liver_sim {

// Colour of a displacement magnitude u (m): a blue-cyan-green-yellow-red ramp from 0 to
// scale_max (m); larger values stay red.
std_msgs::ColorRGBA displacement_colour(double u, double scale_max);

// TRIANGLE_LIST of the boundary triangles at the current positions (m), one colour per vertex
// from its displacement magnitude, with opacity `alpha` (0-1: below 1 the vessels show through).
void fill_mesh_marker(const LiverModel& model, double scale_max, double alpha, visualization_msgs::Marker& marker);

// LINE_LIST of the vessel beams at their current positions (m), one colour per vessel tree.
void fill_vessel_marker(const LiverModel& model, visualization_msgs::Marker& marker);

}  // namespace liver_sim
