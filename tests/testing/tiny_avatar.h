// A tiny avatar configuration for tests of the neural parts: seconds, not minutes.
#pragma once

#include "common/avatar/avatar_config.h"

namespace headcast::testing {

inline AvatarConfig TinyAvatarConfig() {
  AvatarConfig c;
  c.output_size = 128;
  c.num_expression = 13;  // the built-in head's count
  c.feature_channels = 8;
  c.mlp_width = 16;
  c.mlp_layers = 3;
  c.skip_layer = 2;
  c.pe_frequencies = 2;
  c.samples_per_ray = 4;
  c.renderer_channels = {8, 8, 4, 4};
  return c;
}

}  // namespace headcast::testing
