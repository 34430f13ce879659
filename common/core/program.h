// What every program's main shares: parse the flags, run, and turn an
// exception (bad configuration, a bad file) into one logged line and exit 1.
#pragma once

#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <atomic>
#include <csignal>
#include <exception>
#include <functional>
#include <stdexcept>
#include <string>
#include <type_traits>

namespace headcast {

// SIGINT and SIGTERM set `*stop` (a program's loops poll it and end cleanly).
inline void StopOnSignals(std::atomic<bool>* stop) {
  static std::atomic<bool>* flag = nullptr;
  flag = stop;
  std::signal(SIGINT, [](int) { *flag = true; });
  std::signal(SIGTERM, [](int) { *flag = true; });
}

// --config FILE (TOML/INI, key = value). A key that names no option is an
// error naming it, not silently dropped: a misspelt tls-client-ca would
// otherwise turn mutual TLS off without a word.
inline void AddConfigFile(CLI::App& app) {
  app.set_config("--config", "", "read options from this file (TOML/INI: key = value; unknown keys are errors)");
  app.allow_config_extras(CLI::config_extras_mode::error);
}

// A number the user typed (a flag's value, a key in a file), whole: "1.5x",
// "" or "abc" are errors that name `what` and repeat the text, not "stod".
template <typename T>
T ParseNumber(const std::string& text, const std::string& what) {
  static_assert(std::is_arithmetic_v<T>);
  size_t used = 0;
  T value{};
  try {
    if constexpr (std::is_floating_point_v<T>)
      value = static_cast<T>(std::stod(text, &used));
    else
      value = static_cast<T>(std::stoll(text, &used));
  } catch (const std::exception&) {
    used = std::string::npos;
  }
  if (used != text.size() || text.empty())
    throw std::invalid_argument(what + ": '" + text + "' is not " +
                                (std::is_floating_point_v<T> ? "a number" : "a whole number"));
  return value;
}

inline int RunProgram(CLI::App& app, int argc, char** argv, const std::function<int()>& run) {
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  try {
    return run();
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
}

}  // namespace headcast
