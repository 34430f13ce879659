// Helpers for options structs' Check(): collect every problem, then throw one clear message.
#pragma once

#include <string>
#include <vector>

namespace headcast {

class OptionsCheck {
 public:
  explicit OptionsCheck(std::string owner) : owner_(std::move(owner)) {}

  OptionsCheck& Positive(const char* name, double value);
  OptionsCheck& NonNegative(const char* name, double value);
  OptionsCheck& Finite(const char* name, double value);
  OptionsCheck& InRange(const char* name, double value, double lo, double hi);  // inclusive
  OptionsCheck& NotEmpty(const char* name, const std::string& value);
  // Empty passes (an optional file); otherwise the file must open for reading.
  OptionsCheck& ReadableFile(const char* name, const std::string& path);
  OptionsCheck& That(bool condition, const std::string& message);

  bool ok() const { return errors_.empty(); }
  const std::vector<std::string>& errors() const { return errors_; }
  // Throws std::invalid_argument("<owner>: <error>; <error>") if anything failed.
  void ThrowIfErrors() const;

 private:
  std::string owner_;
  std::vector<std::string> errors_;
};

}  // namespace headcast
