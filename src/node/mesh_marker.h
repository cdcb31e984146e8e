// Conversion of the model's deformed surface into an rviz marker.
#pragma once

#include <std_msgs/ColorRGBA.h>
#include <visualization_msgs/Marker.h>

#include "liver_sim/liver_model.h"

namespace liver_sim {

// Colour of a displacement magnitude u (m): a blue-cyan-green-yellow-red ramp from 0 to
// scale_max (m); larger values stay red.
std_msgs::ColorRGBA displacement_colour(double u, double scale_max);

// TRIANGLE_LIST of the boundary triangles at the current positions (m), one colour per vertex
// from its displacement magnitude.
void fill_mesh_marker(const LiverModel& model, double scale_max, visualization_msgs::Marker& marker);

}  // namespace liver_sim
