// Head models shared by the head-model tests (built once per process).
#pragma once

#include "common/headmodel/builtin_head.h"

namespace headcast::testing {

inline const HeadModel& Builtin() {
  static const HeadModel model = MakeBuiltinHead();
  return model;
}

// Random parameters in the useful range (shape/expression in [-1, 1], pose a few tenths of a radian).
HeadModelParams RandomParams(const HeadModel& model, unsigned seed, double pose_scale = 0.3);

}  // namespace headcast::testing
