// Synthetic talking-head motion.
#include "common/headmodel/synthetic_motion.h"

#include <cmath>

#include "common/core/options.h"
#include "common/headmodel/head_render.h"

namespace headcast {

void SyntheticMotionOptions::Check() const {
  OptionsCheck c("SyntheticMotionOptions");
  c.Positive("fps", fps).InRange("distance", distance, 0.1, 10).InRange("max_yaw_deg", max_yaw_deg, 0, 90);
  c.InRange("max_pitch_deg", max_pitch_deg, 0, 60).InRange("expression_scale", expression_scale, 0, 3);
  c.ThrowIfErrors();
}

FrameParams SyntheticTalkingHead(const HeadModel& model, int index, const SyntheticMotionOptions& o) {
  const double t = index / o.fps;
  const double phase = 0.7 * o.seed;
  FrameParams p;
  p.sequence = static_cast<uint64_t>(index);
  p.capture_time_s = t;
  p.expression = Eigen::VectorXf::Zero(model.num_expression());
  // Speech: the mouth opens and closes a few times a second, in bursts.
  const double syllables =
      std::max(0.0, std::sin(2 * M_PI * 3.1 * t + phase)) * (0.6 + 0.4 * std::sin(2 * M_PI * 0.4 * t));
  // Blinks: ~150 ms every ~3.5 s.
  const double blink_phase = std::fmod(t + 0.37 * o.seed, 3.5);
  const double blink = blink_phase < 0.15 ? std::sin(M_PI * blink_phase / 0.15) : 0.0;
  auto set = [&](const char* name, double value) {
    const int i = model.ExpressionIndex(name);
    if (i >= 0) p.expression[i] = static_cast<float>(value);
    return i >= 0;
  };
  bool named = false;
  if (model.JointIsArticulated(kJawJoint)) {
    p.jaw = Eigen::Vector3f(static_cast<float>(0.22 * syllables), 0, 0);
  } else {
    named |= set("jawOpen", 0.5 * syllables);
  }
  named |= set("blink_left", blink) | set("blink_right", blink) | set("eyeBlink_L", blink) | set("eyeBlink_R", blink);
  const double smile = o.expression_scale * 0.5 * (1 + std::sin(2 * M_PI * 0.11 * t + phase));
  named |= set("smile", smile) | set("mouthSmile_L", 0.6 * smile) | set("mouthSmile_R", 0.6 * smile);
  named |= set("brow_raise", o.expression_scale * 0.6 * std::max(0.0, std::sin(2 * M_PI * 0.23 * t + 1 + phase)));
  named |= set("browInnerUp_L", 0.4 * std::max(0.0, std::sin(2 * M_PI * 0.23 * t + 1 + phase)));
  named |= set("pucker", o.expression_scale * 0.4 * std::max(0.0, std::sin(2 * M_PI * 0.17 * t + 2 + phase)));
  if (!named) {
    for (int e = 0; e < model.num_expression(); ++e)
      p.expression[e] =
          static_cast<float>(o.expression_scale * 0.5 * std::sin(2 * M_PI * (0.05 + 0.013 * e) * t + e + phase));
  }
  // Gaze wanders a little; both eyes alike.
  const Eigen::Vector3f gaze(static_cast<float>(0.08 * std::sin(2 * M_PI * 0.13 * t + phase)),
                             static_cast<float>(0.15 * std::sin(2 * M_PI * 0.09 * t)), 0);
  if (model.JointIsArticulated(kLeftEyeJoint)) p.left_eye = p.right_eye = gaze;
  const double yaw = o.max_yaw_deg * std::sin(2 * M_PI * 0.07 * t + phase);
  const double pitch = o.max_pitch_deg * std::sin(2 * M_PI * 0.05 * t + 0.5 * phase);
  // Centre the view on the model's landmarks so any model (metres, any origin) is framed.
  const Eigen::Vector3d target = model.rest_landmark_centroid() + Eigen::Vector3d(0, -0.01, 0);
  p.SetCamFromHead(FrontalCamFromHead(o.distance, yaw, pitch, target));
  return p;
}

}  // namespace headcast
