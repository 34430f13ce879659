// Which of a head model's vertices move only with the skull.
#pragma once

#include <algorithm>

#include "common/headmodel/head_model.h"

namespace headcast {

// Vertex `v` is carried neither by the jaw nor by an eye, and no expression
// coefficient moves it by more than a millimetre per unit: forehead,
// hairline, crown, what follows the head's placement alone.
inline bool MovesOnlyWithTheSkull(const HeadModel& model, int v) {
  const HeadModelData& d = model.data();
  if (d.weights(v, kJawJoint) > 0 || d.weights(v, kLeftEyeJoint) > 0 || d.weights(v, kRightEyeJoint) > 0) return false;
  double moved = 0;
  for (int k = 0; k < model.num_expression(); ++k)
    moved = std::max<double>(moved, d.expressiondirs.block(3 * v, k, 3, 1).norm());
  return moved <= 1e-3;
}

}  // namespace headcast
