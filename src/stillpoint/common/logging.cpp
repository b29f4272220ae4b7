#include "stillpoint/common/logging.hpp"

#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include "stillpoint/common/error.hpp"

namespace sp {

void setup_logging(const std::string& level) {
  const auto lvl = spdlog::level::from_str(level);
  if (lvl == spdlog::level::off && level != "off") throw Error("unknown log level '" + level + "'");
  // Called again (a second stillpoint::System in one process): the logger exists, only the level changes.
  auto logger = spdlog::get("stillpoint");
  if (!logger) {
    logger = spdlog::stderr_color_mt("stillpoint");
    logger->set_pattern("[%H:%M:%S.%e] [%^%l%$] %v");
  }
  logger->set_level(lvl);
  spdlog::set_default_logger(logger);
}

}  // namespace sp
