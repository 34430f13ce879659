// Timing: a stopwatch and order statistics of repeated measurements.
#pragma once

#include <chrono>
#include <vector>

namespace headcast {

class Stopwatch {
 public:
  Stopwatch() : start_(Clock::now()) {}
  void Restart() { start_ = Clock::now(); }
  double ElapsedSeconds() const { return std::chrono::duration<double>(Clock::now() - start_).count(); }
  double ElapsedMs() const { return ElapsedSeconds() * 1e3; }
  double ElapsedUs() const { return ElapsedSeconds() * 1e6; }

 private:
  using Clock = std::chrono::steady_clock;
  Clock::time_point start_;
};

// Seconds on the steady clock since an arbitrary epoch; equal across processes
// of one machine (capture timestamps, same-host latency).
double SteadyNowSeconds();

// Samples (e.g. milliseconds per frame) and their summary statistics.
class SampleStats {
 public:
  void Add(double value) { values_.push_back(value); }
  size_t count() const { return values_.size(); }
  bool empty() const { return values_.empty(); }
  double Mean() const;
  double Min() const;
  double Max() const;
  // Linear interpolation between order statistics; p in [0, 100]. NaN if empty.
  double Percentile(double p) const;
  double Median() const { return Percentile(50); }
  const std::vector<double>& values() const { return values_; }

 private:
  std::vector<double> values_;
};

}  // namespace headcast
