// Synthetic parameter sequences: a head that talks, blinks, looks around and
// turns, for demos, benchmarks and loopback tests without a camera.
#pragma once

#include "common/headmodel/head_model.h"
#include "common/headmodel/params.h"

namespace headcast {

struct SyntheticMotionOptions {
  double fps = 30;           // frames per second
  double distance = 0.62;    // camera to head, metres
  double max_yaw_deg = 20;   // head turn amplitude, degrees
  double max_pitch_deg = 8;  // nod amplitude, degrees
  double expression_scale = 0.8;
  unsigned seed = 1;  // varies the phases
  void Check() const;
};

// Frame `index` of a smooth, deterministic sequence. Uses named components when
// the model has them (jaw joint, blink_*, smile, ...; jawOpen/eyeBlink_* for
// ICT-FaceKit), otherwise slow sinusoids on every expression component.
FrameParams SyntheticTalkingHead(const HeadModel& model, int index, const SyntheticMotionOptions& options = {});

}  // namespace headcast
