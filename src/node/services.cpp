#include "services.h"

#include "msg_conversion.h"

namespace liver_sim {

Services::Services(ros::NodeHandle& pnh, TrackingSession& session) : session_(session) {
  reset_srv_ = pnh.advertiseService("reset", &Services::on_reset, this);
  capsule_srv_ = pnh.advertiseService("set_capsule", &Services::on_set_capsule, this);
  align_srv_ = pnh.advertiseService("align_rigidly", &Services::on_align_rigidly, this);
}

bool Services::on_reset(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
  session_.submit(Reset{});
  res.success = true;
  res.message = "back to the rest shape at the next step; instruments released until their next pose";
  return true;
}

bool Services::on_align_rigidly(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
  session_.submit(AlignRigidly{});
  res.success = true;
  res.message = "the next cloud is rigidly aligned (ICP) before it is registered";
  return true;
}

bool Services::on_set_capsule(SetCapsule::Request& req, SetCapsule::Response& res) {
  CapsuleOptions capsule;
  const std::string refusal = session_.submit(to_edit(req), capsule);
  fill_response(refusal, capsule, res);
  return true;
}

}  // namespace liver_sim
