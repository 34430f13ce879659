#pragma once
// The median the tracking and training code take of per-frame and per-point
// samples: robust to the few frames or points a fit got wrong.

#include <algorithm>
#include <cstddef>
#include <stdexcept>
#include <vector>

namespace headcast {

// The upper median of values (the element at size / 2 once sorted), found by a
// partial sort: values' order changes. Throws on an empty vector.
template <typename T>
T MedianInPlace(std::vector<T>& values) {
  if (values.empty()) throw std::invalid_argument("MedianInPlace: no values");
  const auto middle = values.begin() + static_cast<std::ptrdiff_t>(values.size() / 2);
  std::nth_element(values.begin(), middle, values.end());
  return *middle;
}

// As MedianInPlace, on a copy.
template <typename T>
T Median(std::vector<T> values) {
  return MedianInPlace(values);
}

}  // namespace headcast
