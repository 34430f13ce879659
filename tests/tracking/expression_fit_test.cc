// The expression fit's settings as they travel in datasets and avatar files:
// what is written is read back and put into the fitter's options; what is
// malformed is refused, saying which setting.
#include "common/tracking/expression_fit.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace headcast {
namespace {

TEST(ExpressionFitSettings, TravelAsJsonIntoTheFittersOptions) {
  const ExpressionFitSettings s{5, 50, 100, "vertical", 30};
  const ExpressionFitSettings back = ExpressionFitSettings::FromJson(nlohmann::json::parse(s.ToJson().dump()));
  EXPECT_EQ(back, s);
  HeadFitterOptions o;
  o.contour_weight = 0.7;
  back.ApplyTo(&o);
  EXPECT_EQ(o.expression_prior, 5);
  EXPECT_EQ(o.expression_range_weight, 50);
  EXPECT_EQ(o.eye_look_prior, 100);
  EXPECT_EQ(o.eye_look_prior_shapes, "vertical");
  EXPECT_EQ(o.lid_gaze_weight, 30);
  EXPECT_EQ(o.contour_weight, 0.7);  // the rest of the fit is not theirs
  EXPECT_EQ(ExpressionFitSettings::Of(o), s);
  o.Check();
  // Files from before carry none: they were fitted with the settings of then.
  const ExpressionFitSettings legacy = ExpressionFitSettings::Legacy();
  EXPECT_EQ(legacy.expression_prior, 2e-3);
  EXPECT_EQ(legacy.eye_look_prior, 0);
  EXPECT_EQ(legacy.lid_gaze_weight, 0);
  // Files written before the lids' tie to the gaze was a setting were fitted without it.
  nlohmann::json before = s.ToJson();
  before.erase("lid_gaze_weight");
  EXPECT_EQ(ExpressionFitSettings::FromJson(before).lid_gaze_weight, 0);
}

TEST(ExpressionFitSettings, RefuseWhatIsMalformedByName) {
  const nlohmann::json good = ExpressionFitSettings{}.ToJson();
  auto refused = [](const nlohmann::json& bad, const std::string& says) {
    try {
      ExpressionFitSettings::FromJson(bad);
      ADD_FAILURE() << "accepted: " << bad.dump();
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(says), std::string::npos) << e.what();
    }
  };
  nlohmann::json bad = good;
  bad.erase("expression_prior");
  refused(bad, "tracking_fit.expression_prior wants a number");
  bad = good;
  bad["expression_range_weight"] = "100";
  refused(bad, "tracking_fit.expression_range_weight wants a number");
  bad = good;
  bad["eye_look_prior"] = -1;
  refused(bad, "tracking_fit.eye_look_prior wants a finite non-negative number");
  bad = good;
  bad["lid_gaze_weight"] = -2;
  refused(bad, "tracking_fit.lid_gaze_weight wants a finite non-negative number");
  bad = good;
  bad["lid_gaze_weight"] = "1";
  refused(bad, "tracking_fit.lid_gaze_weight wants a number");
  bad = good;
  bad["expression_prior"] = std::numeric_limits<double>::infinity();
  refused(bad, "tracking_fit.expression_prior wants a finite");
  bad = good;
  bad["eye_look_prior_shapes"] = "sideways";
  refused(bad, "must be all or vertical, not \"sideways\"");
  bad = good;
  bad["eye_look_prior_shapes"] = 2;
  refused(bad, "tracking_fit.eye_look_prior_shapes wants a string");
  refused(nlohmann::json::array(), "tracking_fit.expression_prior wants a number");
}

// The options structs that hold the settings (the fitter's, prep's) check
// them one way: each bad field named.
TEST(ExpressionFitSettings, TheOptionsHoldingThemRefuseBadOnesByName) {
  auto says = [](const ExpressionFitSettings& s) {
    OptionsCheck c("Holder");
    s.CheckInto(&c);
    try {
      c.ThrowIfErrors();
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_EQ(says(ExpressionFitSettings{}), "");
  ExpressionFitSettings bad;
  bad.expression_prior = std::nan("");
  bad.eye_look_prior_shapes = "sideways";
  bad.lid_gaze_weight = -1;
  const std::string message = says(bad);
  EXPECT_NE(message.find("expression_prior"), std::string::npos) << message;
  EXPECT_NE(message.find("must be all or vertical, not \"sideways\""), std::string::npos) << message;
  EXPECT_NE(message.find("lid_gaze_weight"), std::string::npos) << message;
  HeadFitterOptions fitter;
  fitter.expression_range_weight = -1;
  EXPECT_THROW(fitter.Check(), std::invalid_argument);
}

}  // namespace
}  // namespace headcast
