// Logging set-up.
#include "common/core/log.h"

#include <spdlog/sinks/stdout_color_sinks.h>

#include <cstdlib>
#include <stdexcept>

namespace headcast {
void InitLogging(const std::string& level_name) {
  std::string name = level_name;
  if (name.empty()) {
    const char* env = std::getenv("HEADCAST_LOG");
    name = env ? env : "info";
  }
  const auto level = spdlog::level::from_str(name);
  if (level == spdlog::level::off && name != "off")
    throw std::invalid_argument("unknown log level '" + name + "' (trace, debug, info, warn, error, off)");
  // Logs go to stderr: programs print their results (JSON) on stdout.
  static const auto logger = [] {
    auto l = spdlog::stderr_color_mt("headcast");
    spdlog::set_default_logger(l);
    return l;
  }();
  (void)logger;
  spdlog::set_level(level);
  spdlog::set_pattern("[%H:%M:%S.%e] [%^%l%$] %v");
}
}  // namespace headcast
