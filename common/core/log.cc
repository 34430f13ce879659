// Logging set-up.
#include "common/core/log.h"

#include <spdlog/sinks/stdout_color_sinks.h>

#include <cstdlib>
#include <stdexcept>

namespace headcast {

std::string Printable(const std::string& text, size_t max_bytes) {
  std::string out = text.substr(0, max_bytes);
  for (char& c : out)
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) c = '?';
  if (text.size() > max_bytes) out += "...(" + std::to_string(text.size() - max_bytes) + " more bytes)";
  return out;
}
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
