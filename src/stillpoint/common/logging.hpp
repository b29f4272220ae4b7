#pragma once
#include <string>

namespace sp {
// Configures the default spdlog logger: level name (trace|debug|info|warn|error|off), stderr sink.
void setup_logging(const std::string& level);
}  // namespace sp
