// What every program's main shares: parse the flags, run, and turn an
// exception (bad configuration, a bad file) into one logged line and exit 1.
#pragma once

#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <cctype>
#include <csignal>
#include <exception>
#include <functional>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

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

// Options structs check themselves and name their fields (tls_ca); the user
// typed flags (--tls-ca). In `message`, every field that is the long name of
// a flag of `app` or of its subcommands becomes that flag: names with an
// underscore wherever they stand, one-word names where a check states a bound
// ("iterations must be > 0"), so that ordinary words stay words; a name after
// a dot is a file's key and stays.
inline std::string InFlagNames(const CLI::App& app, std::string message) {
  std::vector<const CLI::App*> apps = {&app};
  for (size_t i = 0; i < apps.size(); ++i)
    for (const CLI::App* sub : apps[i]->get_subcommands([](const CLI::App*) { return true; })) apps.push_back(sub);
  auto is_word = [](char c) { return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-'; };
  for (const CLI::App* a : apps)
    for (const CLI::Option* option : a->get_options()) {
      for (const std::string& name : option->get_lnames()) {
        std::string field = name;
        std::replace(field.begin(), field.end(), '-', '_');
        const bool compound = field.find('_') != std::string::npos;
        for (size_t at = message.find(field); at != std::string::npos; at = message.find(field, at + 1)) {
          const size_t end = at + field.size();
          // After a dot the name is a key in a file's entry (tracking_fit.expression_prior), not a flag.
          if ((at > 0 && (is_word(message[at - 1]) || message[at - 1] == '.')) ||
              (end < message.size() && is_word(message[end])))
            continue;
          if (!compound && message.compare(end, 6, " must ") != 0) continue;
          message.replace(at, field.size(), "--" + name);
          at += 1;
        }
      }
    }
  return message;
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
    spdlog::error("{}", InFlagNames(app, e.what()));
    return 1;
  }
}

}  // namespace headcast
