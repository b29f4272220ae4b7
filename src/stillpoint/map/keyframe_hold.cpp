#include "stillpoint/map/keyframe_hold.hpp"

#include <utility>

namespace sp::map {

KeyframeHold::KeyframeHold(KeyframeHold&& other) noexcept
    : map_(other.map_), held_(std::exchange(other.held_, {})) {}

KeyframeHold& KeyframeHold::operator=(KeyframeHold&& other) noexcept {
  if (this != &other) {
    if (!held_.empty() && map_ != nullptr) {
      MapView view = map_->view();
      release(view);
    }
    map_ = other.map_;
    held_ = std::exchange(other.held_, {});
  }
  return *this;
}

KeyframeHold::~KeyframeHold() {
  if (held_.empty() || map_ == nullptr) return;
  MapView view = map_->view();
  release(view);
}

bool KeyframeHold::add(MapView& view, KeyframeId kf) {
  if (!view.hold_keyframe(kf)) return false;
  held_.push_back(kf);
  return true;
}

void KeyframeHold::release(MapView& view) {
  for (KeyframeId kf : held_) view.release_keyframe(kf);
  held_.clear();
}

}  // namespace sp::map
