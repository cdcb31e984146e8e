// The node's services, each a request handed to the session for its next frame: ~reset (the rest
// shape, instruments released), ~set_capsule (checked now, answered with the capsule the model
// will have), ~align_rigidly (the next cloud aligned by ICP first).
#pragma once

#include <ros/ros.h>
#include <std_srvs/Trigger.h>

#include "liver_sim/SetCapsule.h"
#include "liver_sim/session/tracking_session.h"

namespace liver_sim {

class Services {
 public:
  Services(ros::NodeHandle& pnh, TrackingSession& session);

 private:
  bool on_reset(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res);
  bool on_align_rigidly(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res);
  bool on_set_capsule(SetCapsule::Request& req, SetCapsule::Response& res);

  TrackingSession& session_;
  ros::ServiceServer reset_srv_, capsule_srv_, align_srv_;
};

}  // namespace liver_sim
