#include "stillpoint/api/system_access.hpp"

#include <memory>

#include "stillpoint/api/system_impl.hpp"
#include "stillpoint/common/error.hpp"

namespace stillpoint::internal {

System SystemAccess::create(const sp::pipeline::SystemConfig& config, const sp::io::CameraConfig& camera,
                            const sp::pipeline::SystemOptions& options) {
  auto impl = std::make_unique<System::Impl>();
  impl->camera = camera;
  impl->system = std::make_unique<sp::pipeline::SlamSystem>(config, camera, options);
  return System(std::move(impl));
}

TrackResult SystemAccess::track(System& system, const sp::io::FrameData& frame) {
  if (!system.impl_ || system.impl_->shut_down)
    throw sp::Error("SystemAccess::track: the system is shut down");
  return system.impl_->track(frame);
}

sp::pipeline::SlamSystem& SystemAccess::pipeline(System& system) {
  if (!system.impl_) throw sp::Error("SystemAccess::pipeline: moved-from system");
  return *system.impl_->system;
}

}  // namespace stillpoint::internal
