// Options checking.
#include "common/core/options.h"

#include <cmath>
#include <fstream>
#include <sstream>
#include <stdexcept>

namespace headcast {
namespace {
std::string Num(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}
}  // namespace

OptionsCheck& OptionsCheck::Positive(const char* name, double v) {
  if (!(v > 0) || !std::isfinite(v)) errors_.push_back(std::string(name) + " must be > 0 (got " + Num(v) + ")");
  return *this;
}
OptionsCheck& OptionsCheck::NonNegative(const char* name, double v) {
  if (!(v >= 0) || !std::isfinite(v)) errors_.push_back(std::string(name) + " must be >= 0 (got " + Num(v) + ")");
  return *this;
}
OptionsCheck& OptionsCheck::Finite(const char* name, double v) {
  if (!std::isfinite(v)) errors_.push_back(std::string(name) + " must be finite (got " + Num(v) + ")");
  return *this;
}
OptionsCheck& OptionsCheck::InRange(const char* name, double v, double lo, double hi) {
  if (!(v >= lo && v <= hi))
    errors_.push_back(std::string(name) + " must be in [" + Num(lo) + ", " + Num(hi) + "] (got " + Num(v) + ")");
  return *this;
}
OptionsCheck& OptionsCheck::NotEmpty(const char* name, const std::string& v) {
  if (v.empty()) errors_.push_back(std::string(name) + " must not be empty");
  return *this;
}
OptionsCheck& OptionsCheck::ReadableFile(const char* name, const std::string& path) {
  if (!path.empty() && !std::ifstream(path).good())
    errors_.push_back(std::string(name) + ": cannot read " + path + " (does it exist, and may we read it?)");
  return *this;
}
OptionsCheck& OptionsCheck::That(bool condition, const std::string& message) {
  if (!condition) errors_.push_back(message);
  return *this;
}

void OptionsCheck::ThrowIfErrors() const {
  if (errors_.empty()) return;
  std::string msg = owner_ + ": ";
  for (size_t i = 0; i < errors_.size(); ++i) msg += (i ? "; " : "") + errors_[i];
  throw std::invalid_argument(msg);
}

}  // namespace headcast
