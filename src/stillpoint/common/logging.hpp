#pragma once
#include <string>

namespace sp {
// Configures the default spdlog logger: level name (trace|debug|info|warn|error|off), stderr sink.
// May be called again: later calls only change the level.
void setup_logging(const std::string& level);
}  // namespace sp
