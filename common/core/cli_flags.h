// Flags that mean the same thing in every program get one name everywhere:
// --json for the machine-readable report, --pacing for how recorded input is
// played, --max-frames for a frame limit. Names earlier versions used stay
// accepted (hidden from --help, also as config-file keys) so that scripts
// and configs written for them keep working.
#pragma once

#include <CLI/CLI.hpp>
#include <initializer_list>
#include <string>

namespace headcast {

// Hidden aliases: bound to the same variable, absent from --help.
inline void AddHiddenAliases(CLI::App& app, std::initializer_list<const char*> names, std::string* value) {
  for (const char* name : names) app.add_option(name, *value)->group("");
}

// --json FILE: the program's machine-readable report.
inline CLI::Option* AddJsonFlag(CLI::App& app, std::string* path, const std::string& what,
                                std::initializer_list<const char*> old_names = {}) {
  AddHiddenAliases(app, old_names, path);
  return app.add_option("--json", *path, "write " + what + " here (JSON)");
}

// --max-frames N: stop after N frames (0 or unset: all).
template <typename Int>
CLI::Option* AddMaxFramesFlag(CLI::App& app, Int* count, const std::string& what,
                              std::initializer_list<const char*> old_names = {}) {
  for (const char* name : old_names) app.add_option(name, *count)->group("")->check(CLI::NonNegativeNumber);
  return app.add_option("--max-frames", *count, what)->check(CLI::NonNegativeNumber);
}

// --pacing realtime|none: recorded inputs played at their frame rate (as a
// camera would deliver them) or as fast as the program goes. Each program
// keeps its own default (live programs pace, offline ones do not).
inline CLI::Option* AddPacingFlag(CLI::App& app, bool* realtime, std::initializer_list<const char*> old_realtime = {},
                                  std::initializer_list<const char*> old_unpaced = {}) {
  for (const char* name : old_realtime) app.add_flag_callback(name, [realtime] { *realtime = true; })->group("");
  for (const char* name : old_unpaced) app.add_flag_callback(name, [realtime] { *realtime = false; })->group("");
  return app
      .add_option_function<std::string>(
          "--pacing", [realtime](const std::string& v) { *realtime = v == "realtime"; },
          std::string("recorded inputs: 'realtime' (at their frame rate) or 'none' (as fast as possible); default ") +
              (*realtime ? "realtime" : "none"))
      ->check(CLI::IsMember({"realtime", "none"}));
}

}  // namespace headcast
