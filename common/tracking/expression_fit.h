// What decides the meaning of a fitted frame's expression coefficients: the
// prior on them, how hard they are held in the model's range and the eyeLook
// prior. An avatar learns the codes its training frames were fitted with, so
// the live sender must fit with the same settings or its codes mean something
// else to the networks. The settings travel in the dataset and the avatar file.
#pragma once

#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "common/core/options.h"
#include "common/tracking/head_fitter.h"

namespace headcast {

struct ExpressionFitSettings {
  double expression_prior = HeadFitterOptions{}.expression_prior;
  double expression_range_weight = HeadFitterOptions{}.expression_range_weight;
  double eye_look_prior = HeadFitterOptions{}.eye_look_prior;
  std::string eye_look_prior_shapes = HeadFitterOptions{}.eye_look_prior_shapes;
  double lid_gaze_weight = HeadFitterOptions{}.lid_gaze_weight;

  static ExpressionFitSettings Of(const HeadFitterOptions& o);
  void ApplyTo(HeadFitterOptions* o) const;
  nlohmann::json ToJson() const;
  // Adds to `c` what is wrong with the settings: a negative or non-finite
  // weight, shapes other than kEyeLookPriorShapes (the options structs that
  // hold them check them this way).
  void CheckInto(OptionsCheck* c) const;
  // Throws std::invalid_argument on a missing or mistyped key, a negative or
  // non-finite weight, or shapes other than kEyeLookPriorShapes. A missing
  // lid_gaze_weight is 0: files from before it was a setting were fitted without.
  static ExpressionFitSettings FromJson(const nlohmann::json& j);
  // What files from before the settings travelled were fitted with (the
  // defaults of then; their eyeLook prior, where the dataset recorded one, is
  // taken from its record).
  static ExpressionFitSettings Legacy();
};

bool operator==(const ExpressionFitSettings& a, const ExpressionFitSettings& b);

}  // namespace headcast
