// Logging through spdlog, with one place that sets the level from flags or HEADCAST_LOG.
#pragma once

#include <spdlog/spdlog.h>

#include <string>

namespace headcast {
// level: trace, debug, info, warn, error, off. Empty means HEADCAST_LOG or "info".
// Throws std::invalid_argument for an unknown level name.
void InitLogging(const std::string& level = "");

// Text from outside (a peer's names, a file's fields) made safe to log or echo:
// control characters become '?', and beyond `max_bytes` it is cut, saying how
// much was left out. No newline a peer sends can forge a log line.
std::string Printable(const std::string& text, size_t max_bytes = 64);
}  // namespace headcast
