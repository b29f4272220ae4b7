#include "stillpoint/common/logging.hpp"

#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include "stillpoint/common/error.hpp"

namespace sp {

void setup_logging(const std::string& level) {
  auto logger = spdlog::stderr_color_mt("stillpoint");
  logger->set_pattern("[%H:%M:%S.%e] [%^%l%$] %v");
  const auto lvl = spdlog::level::from_str(level);
  if (lvl == spdlog::level::off && level != "off") throw Error("unknown log level '" + level + "'");
  logger->set_level(lvl);
  spdlog::set_default_logger(logger);
}

}  // namespace sp
