// Logging through spdlog, with one place that sets the level from flags or HEADCAST_LOG.
#pragma once

#include <spdlog/spdlog.h>

#include <string>

namespace headcast {
// level: trace, debug, info, warn, error, off. Empty means HEADCAST_LOG or "info".
// Throws std::invalid_argument for an unknown level name.
void InitLogging(const std::string& level = "");
}  // namespace headcast
