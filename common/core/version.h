// --version for every program: the project's version (CMake's PROJECT_VERSION,
// given to every program by headcast_program).
#pragma once

#include <CLI/CLI.hpp>

#ifndef HEADCAST_VERSION
#define HEADCAST_VERSION "unknown"
#endif

namespace headcast {

// CLI11 2.1 prints the text as it is: the newline is ours.
inline void AddVersionFlag(CLI::App& app) { app.set_version_flag("--version", "headcast " HEADCAST_VERSION "\n"); }

}  // namespace headcast
