#include "common/tracking/expression_fit.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace headcast {

ExpressionFitSettings ExpressionFitSettings::Of(const HeadFitterOptions& o) {
  return {o.expression_prior, o.expression_range_weight, o.eye_look_prior, o.eye_look_prior_shapes, o.lid_gaze_weight};
}

void ExpressionFitSettings::ApplyTo(HeadFitterOptions* o) const {
  o->expression_prior = expression_prior;
  o->expression_range_weight = expression_range_weight;
  o->eye_look_prior = eye_look_prior;
  o->eye_look_prior_shapes = eye_look_prior_shapes;
  o->lid_gaze_weight = lid_gaze_weight;
}

void ExpressionFitSettings::CheckInto(OptionsCheck* c) const {
  c->NonNegative("expression_prior", expression_prior)
      .NonNegative("expression_range_weight", expression_range_weight)
      .NonNegative("eye_look_prior", eye_look_prior)
      .NonNegative("lid_gaze_weight", lid_gaze_weight)
      .That(std::find(kEyeLookPriorShapes.begin(), kEyeLookPriorShapes.end(), eye_look_prior_shapes) !=
                kEyeLookPriorShapes.end(),
            "eye_look_prior_shapes must be all or vertical, not \"" + eye_look_prior_shapes + "\"");
}

nlohmann::json ExpressionFitSettings::ToJson() const {
  return {{"expression_prior", expression_prior},
          {"expression_range_weight", expression_range_weight},
          {"eye_look_prior", eye_look_prior},
          {"eye_look_prior_shapes", eye_look_prior_shapes},
          {"lid_gaze_weight", lid_gaze_weight}};
}

ExpressionFitSettings ExpressionFitSettings::FromJson(const nlohmann::json& j) {
  ExpressionFitSettings s;
  auto weight = [&](const char* key) {
    if (!j.is_object() || !j.contains(key) || !j.at(key).is_number())
      throw std::invalid_argument(std::string("tracking_fit.") + key + " wants a number");
    const double v = j.at(key).get<double>();
    if (!std::isfinite(v) || v < 0)
      throw std::invalid_argument(std::string("tracking_fit.") + key + " wants a finite non-negative number, not " +
                                  j.at(key).dump());
    return v;
  };
  s.expression_prior = weight("expression_prior");
  s.expression_range_weight = weight("expression_range_weight");
  s.eye_look_prior = weight("eye_look_prior");
  if (j.contains("lid_gaze_weight")) s.lid_gaze_weight = weight("lid_gaze_weight");
  if (!j.contains("eye_look_prior_shapes") || !j.at("eye_look_prior_shapes").is_string())
    throw std::invalid_argument("tracking_fit.eye_look_prior_shapes wants a string");
  s.eye_look_prior_shapes = j.at("eye_look_prior_shapes").get<std::string>();
  if (std::find(kEyeLookPriorShapes.begin(), kEyeLookPriorShapes.end(), s.eye_look_prior_shapes) ==
      kEyeLookPriorShapes.end())
    throw std::invalid_argument("tracking_fit.eye_look_prior_shapes must be all or vertical, not \"" +
                                s.eye_look_prior_shapes + "\"");
  return s;
}

ExpressionFitSettings ExpressionFitSettings::Legacy() {
  ExpressionFitSettings s;
  s.expression_prior = 2e-3;
  s.expression_range_weight = 100;
  s.eye_look_prior = 0;
  s.eye_look_prior_shapes = "all";
  s.lid_gaze_weight = 0;
  return s;
}

bool operator==(const ExpressionFitSettings& a, const ExpressionFitSettings& b) {
  return a.expression_prior == b.expression_prior && a.expression_range_weight == b.expression_range_weight &&
         a.eye_look_prior == b.eye_look_prior && a.eye_look_prior_shapes == b.eye_look_prior_shapes &&
         a.lid_gaze_weight == b.lid_gaze_weight;
}

}  // namespace headcast
