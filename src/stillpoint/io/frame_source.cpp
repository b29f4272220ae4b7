#include "stillpoint/io/frame_source.hpp"

namespace sp::io {
FrameSource::~FrameSource() = default;
}  // namespace sp::io
