// Recording guidance and its quality check (training/guided_recording.h).
#include "training/guided_recording.h"

#include <gtest/gtest.h>

#include "common/headmodel/builtin_head.h"
#include "common/headmodel/head_render.h"
#include "common/tracking/head_fitter.h"

namespace headcast {
namespace {

// The built-in head's 68 landmarks seen with the head turned by `yaw_deg`.
Landmarks2d TurnedHead(double yaw_deg) {
  static const HeadModel model = MakeBuiltinHead();
  HeadFitter fitter(model);
  FrameParams f;
  f.SetCamFromHead(FrontalCamFromHead(0.6, yaw_deg));
  return fitter.Project(f, PinholeCamera::FromFovY(640, 480, 40));
}

}  // namespace

TEST(GuidedRecording, PromptsFollowTheClock) {
  EXPECT_EQ(GuidePrompt(0, 60), "Look at the camera and say a few words");
  EXPECT_EQ(GuidePrompt(12, 60), "Turn your head slowly left and right");
  EXPECT_EQ(GuidePrompt(45, 60), "Blink a few times, look around with your eyes");
  EXPECT_EQ(GuidePrompt(59.9, 60), "Talk naturally, as in a call");
  EXPECT_EQ(GuidePrompt(70, 60), "Talk naturally, as in a call");
  EXPECT_EQ(GuidePrompt(3, 10), GuidePrompt(18, 60));  // phases scale with the length
}

TEST(GuidedRecording, YawFromLandmarksTellsTheTurn) {
  const double ahead = ApproximateYawDeg(TurnedHead(0));
  EXPECT_LT(std::abs(ahead), 3.0);
  const double left = ApproximateYawDeg(TurnedHead(25)), right = ApproximateYawDeg(TurnedHead(-25));
  EXPECT_GT(std::abs(left), 12.0);
  EXPECT_LT(std::abs(left), 45.0);
  EXPECT_LT(left * right, 0);  // opposite turns, opposite signs
  EXPECT_NEAR(std::abs(left), std::abs(right), 5.0);
  Landmarks2d collapsed;  // no eye distance: no estimate rather than a division by zero
  for (auto& p : collapsed) p.setZero();
  EXPECT_EQ(ApproximateYawDeg(collapsed), 0.0);
}

TEST(GuidedRecording, QualityCheckNamesWhatToFix) {
  GuidedRecordingOptions o;
  o.out_dir = "unused";
  RecordingQuality good;
  good.checked = 100;
  good.faces = 97;
  good.brightness = 120;
  good.yaw_min_deg = -22;
  good.yaw_max_deg = 25;
  JudgeRecording(o, &good);
  EXPECT_TRUE(good.ok());
  EXPECT_TRUE(good.ToJson()["ok"].get<bool>());

  RecordingQuality bad = good;
  bad.faces = 50;
  bad.brightness = 30;
  bad.yaw_min_deg = -3;
  JudgeRecording(o, &bad);
  ASSERT_EQ(bad.problems.size(), 3u);
  EXPECT_NE(bad.problems[0].find("50 %"), std::string::npos) << bad.problems[0];
  EXPECT_NE(bad.problems[1].find("too dark"), std::string::npos) << bad.problems[1];
  EXPECT_NE(bad.problems[2].find("turn further"), std::string::npos) << bad.problems[2];
  EXPECT_FALSE(bad.ToJson()["ok"].get<bool>());

  RecordingQuality none;  // no face at all: one problem, not figures of nothing
  none.checked = 10;
  JudgeRecording(o, &none);
  EXPECT_EQ(none.problems.size(), 1u);
}

}  // namespace headcast
