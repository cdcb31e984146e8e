// Conversion of the model's deformed surface, vessels and targets into rviz markers.
#pragma once

#include <std_msgs/ColorRGBA.h>
#include <std_msgs/Header.h>
#include <visualization_msgs/Marker.h>
#include <visualization_msgs/MarkerArray.h>

#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "liver_sim/simulation/liver_model.h"
#include "liver_sim/registration/registration.h"

namespace liver_sim {

// Colour of a displacement magnitude u (m): a ramp from a pale tissue tone (0) through yellow,
// orange and red to dark red (scale_max, m); larger values stay dark red.
std_msgs::ColorRGBA displacement_colour(double u, double scale_max);

// Unit outward normals at the nodes of the boundary triangles F at positions x (3 #V, m): the
// area-weighted mean of the adjacent triangles' normals; zero rows for interior nodes.
Eigen::MatrixX3d vertex_normals(const Eigen::MatrixX3i& F, const Eigen::VectorXd& x);

// Where the surface's light comes from, in the model frame: the viewer of the package's rviz
// config (config/liver_sim.rviz: in front, -y, and above, +z). rviz lights no surface with
// per-vertex colours, so the markers carry their shading.
extern const Eigen::Vector3d kLightDirection;

// TRIANGLE_LIST of the boundary triangles at the current positions (m). Each vertex is coloured
// by its displacement from `reference` (3 #V, m: the pre-operative equilibrium, or the rest shape)
// on the displacement_colour ramp, darkened by a diffuse light from kLightDirection so that the
// shape shows. `alpha` in [0, 1]: 1 draws an opaque surface; below 1 the vessels show through,
// and the triangles are ordered back to front as seen from kLightDirection, because rviz blends
// a translucent marker's triangles in their order without sorting them.
void fill_mesh_marker(const LiverModel& model, const Eigen::VectorXd& reference, double scale_max, double alpha,
                      visualization_msgs::Marker& marker);

// LINE_LIST of the vessel beams at their current positions (m), one colour per vessel tree.
void fill_vessel_marker(const LiverModel& model, visualization_msgs::Marker& marker);

// A target's label: a probe's name; a bifurcation's vessel initial and number ("portal
// bifurcation 3": "P3"), short enough to stay apart from its neighbours.
std::string target_label(const TrackedTarget& target);

// Where labels of `height` (m) go: above their anchors, each raised by a line until it overlaps
// no label placed before it (the lower anchors first) as seen from the front (x across, z up:
// the package's rviz view); the text's width estimated from its length.
std::vector<Eigen::Vector3d> label_positions(const std::vector<Eigen::Vector3d>& anchors,
                                             const std::vector<std::string>& texts, double height);

// Each target's label as a TEXT_VIEW_FACING marker 6 mm high above it, placed by
// label_positions (namespace "target_names", id = the target's index, as the target spheres), so
// that the spheres stay plain.
void append_target_names(const std::vector<TrackedTarget>& targets, const std_msgs::Header& header,
                         visualization_msgs::MarkerArray& markers);

// The patient's axes at the -x, -y, -z corner of `box` (the model's rest bounding box, m): arrows
// along +x, +y, +z labelled L, P, S (the model frame is LPS: the patient's left, posterior,
// superior); namespace "orientation".
void append_orientation_axes(const Eigen::AlignedBox3d& box, const std_msgs::Header& header,
                             visualization_msgs::MarkerArray& markers);

// The colour scale's legend beside `box` (the model's rest bounding box, m): a vertical bar of
// cubes from 0 (bottom) to scale_max (top, m) beside the box's +x side, labelled in mm, and a
// title; namespace "legend".
void append_colour_legend(const Eigen::AlignedBox3d& box, double scale_max, const std_msgs::Header& header,
                          visualization_msgs::MarkerArray& markers);

}  // namespace liver_sim
