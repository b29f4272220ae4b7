#pragma once
// Keyframes held against culling for as long as this object lives (MapView::hold_keyframe): a stage
// that verifies in one view and writes in a later one (loop closing) keeps the keyframes it relies on.
// Release under a view you already hold with release(view); otherwise the destructor takes a view of
// its own, so never let a hold die while this thread holds a view of the same map.
#include <vector>

#include "stillpoint/map/map.hpp"

namespace sp::map {

class KeyframeHold {
 public:
  KeyframeHold() = default;
  explicit KeyframeHold(Map& map) : map_(&map) {}
  KeyframeHold(const KeyframeHold&) = delete;
  KeyframeHold& operator=(const KeyframeHold&) = delete;
  KeyframeHold(KeyframeHold&& other) noexcept;
  KeyframeHold& operator=(KeyframeHold&& other) noexcept;
  ~KeyframeHold();

  // Holds kf; false (nothing held) when it is missing or already culled.
  bool add(MapView& view, KeyframeId kf);
  // Releases every keyframe held; the hold is empty afterwards.
  void release(MapView& view);
  [[nodiscard]] const std::vector<KeyframeId>& keyframes() const { return held_; }

 private:
  Map* map_ = nullptr;
  std::vector<KeyframeId> held_;
};

}  // namespace sp::map
