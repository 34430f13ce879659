// Summary statistics of timings.
#include "common/core/timer.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numeric>

namespace headcast {

std::string HumanDuration(double seconds) {
  char text[32];
  if (!(seconds < 90))
    std::snprintf(text, sizeof(text), seconds < 600 ? "%.1f min" : "%.0f min", seconds / 60);
  else
    std::snprintf(text, sizeof(text), "%.0f s", std::max(0.0, seconds));
  return text;
}

double SteadyNowSeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

void SampleStats::Add(double value) {
  ++seen_;
  if (max_kept_ == 0 || values_.size() < max_kept_) {
    values_.push_back(value);
    return;
  }
  random_ ^= random_ << 13;
  random_ ^= random_ >> 7;
  random_ ^= random_ << 17;
  const uint64_t slot = random_ % seen_;  // keep the new sample with probability max_kept / seen
  if (slot < max_kept_) values_[slot] = value;
}

double SampleStats::Mean() const {
  if (values_.empty()) return std::numeric_limits<double>::quiet_NaN();
  return std::accumulate(values_.begin(), values_.end(), 0.0) / values_.size();
}
double SampleStats::Min() const {
  return values_.empty() ? std::numeric_limits<double>::quiet_NaN() : *std::min_element(values_.begin(), values_.end());
}
double SampleStats::Max() const {
  return values_.empty() ? std::numeric_limits<double>::quiet_NaN() : *std::max_element(values_.begin(), values_.end());
}
double SampleStats::Percentile(double p) const {
  if (values_.empty()) return std::numeric_limits<double>::quiet_NaN();
  std::vector<double> v = values_;
  std::sort(v.begin(), v.end());
  const double pos = std::clamp(p, 0.0, 100.0) / 100.0 * (v.size() - 1);
  const size_t lo = static_cast<size_t>(std::floor(pos));
  const size_t hi = std::min(lo + 1, v.size() - 1);
  return v[lo] + (pos - lo) * (v[hi] - v[lo]);
}

}  // namespace headcast
