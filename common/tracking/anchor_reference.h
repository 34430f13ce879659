// What the photometric anchor (photometric_anchor.h) is made with and what it
// learns of a person's face, as data: its options and each point's reference
// grey level, and their JSON, which travels in datasets and avatar files.
// Kept apart from the alignment (Ceres) so that readers of those files and the
// files fuzzer need none of it.
#pragma once

#include <nlohmann/json.hpp>
#include <vector>

namespace headcast {

struct PhotometricAnchorOptions {
  // Each anchored point's weight against a landmark when the frame is fitted
  // again (HeadFitterOptions::rigid_flow_weight of that fit); 0: off.
  double weight = 0;
  int points = 400;        // surface points sampled on the rigid head
  int fit_points = 64;     // of them, the aligned ones each refit holds the pose to
  int rounds = 2;          // reference from the fits, align, fit again
  double blur_iod = 0.03;  // the grey image's Gaussian blur, in eye distances (the alignment's reach)
  double huber = 0.04;     // robust scale of a grey-level residual (0..1): hair over the forehead, glasses' glints
  // Where landmarks and appearance disagree by more than this many eye
  // distances (mean movement of the points), the alignment is not trusted
  // and the frame keeps its landmark fit.
  double max_shift_iod = 0.15;
  void Check() const;
  bool enabled() const { return weight > 0; }
  nlohmann::json ToJson() const;
  // Throws std::invalid_argument on a missing or mistyped key, or values out of range.
  static PhotometricAnchorOptions FromJson(const nlohmann::json& j);
};

// What an offline pass learnt of a person's face for the anchor: the options
// its points were made with and each point's reference grey level. It travels
// in the dataset and the avatar, so that the live sender holds the head to the
// same appearance the avatar's training frames were fitted to: the avatar is
// driven by the rule it was trained with.
struct AnchorReference {
  PhotometricAnchorOptions options;
  std::vector<double> grey;  // one per point (options.points), 0..1; NaN: none
  int referenced() const;
  nlohmann::json ToJson() const;  // a point without a reference is null
  // Throws std::invalid_argument on a malformed entry: bad options, a count
  // other than options.points, a grey level outside 0..1, or fewer referenced
  // points than an alignment needs.
  static AnchorReference FromJson(const nlohmann::json& j);
};

// Fewer referenced points than this and an alignment does not run.
inline constexpr int kMinAlignPoints = 12;

}  // namespace headcast
