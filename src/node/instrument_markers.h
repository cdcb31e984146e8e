// The instruments as rviz markers (namespace "instruments"), each as what it is, from its tip pose
// P (+z back along it): a probe's sphere, a shaft's rounded rod, a tube's wall around its darker
// lumen, a grasper's shaft with two darker jaws on a hinge pin at its end (apart when open).
// Instruments out of the scene are not drawn; the array starts by deleting the last one's markers.
#pragma once

#include <std_msgs/Header.h>
#include <visualization_msgs/MarkerArray.h>

#include <vector>

#include "liver_sim/session/instrument_slots.h"
#include "liver_sim/simulation/liver_model.h"

namespace liver_sim {

visualization_msgs::MarkerArray instrument_markers(const LiverModel& model, const std::vector<InstrumentSlots::Slot>& slots,
                                                   const std_msgs::Header& header);

}  // namespace liver_sim
