// Timing: a stopwatch and order statistics of repeated measurements.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <string>
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

// "35 s", "4.3 min", "25 min": what a person reads in a progress line.
std::string HumanDuration(double seconds);

// Seconds on the steady clock since an arbitrary epoch; equal across processes
// of one machine (capture timestamps, same-host latency).
double SteadyNowSeconds();

// Samples (e.g. milliseconds per frame) and their summary statistics.
class SampleStats {
 public:
  // `max_kept` > 0: a long-running process keeps at most that many samples, a
  // uniform random subset of all it saw (reservoir sampling), so statistics
  // stay unbiased and memory stays bounded. 0: every sample is kept.
  explicit SampleStats(size_t max_kept = 0) : max_kept_(max_kept) {}
  void Add(double value);
  size_t count() const { return seen_; }  // samples added, kept or not
  bool empty() const { return values_.empty(); }
  double Mean() const;
  double Min() const;
  double Max() const;
  // Linear interpolation between order statistics; p in [0, 100]. NaN if empty.
  double Percentile(double p) const;
  double Median() const { return Percentile(50); }
  const std::vector<double>& values() const { return values_; }  // the samples kept

 private:
  size_t max_kept_ = 0;
  size_t seen_ = 0;
  uint64_t random_ = 0x9E3779B97F4A7C15ull;  // xorshift state: the same subset run after run
  std::vector<double> values_;
};

}  // namespace headcast
