// Expression-fidelity figures: landmark agreement and blink correlation.
#include "training/landmark_agreement.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "tests/testing/test_data.h"

namespace headcast {
namespace {

// A neutral 68-point layout with eyes of width 30 and lids `open` apart.
Landmarks2d Eyes(double open) {
  Landmarks2d l{};
  for (int o : {36, 42}) {
    const double x0 = o == 36 ? 100 : 160;
    l[o] = {x0, 100};
    l[o + 3] = {x0 + 30, 100};
    l[o + 1] = {x0 + 10, 100 - open / 2};
    l[o + 2] = {x0 + 20, 100 - open / 2};
    l[o + 5] = {x0 + 10, 100 + open / 2};
    l[o + 4] = {x0 + 20, 100 + open / 2};
  }
  return l;
}

// The first frame of talking_d9 at 256², as the avatar's pictures are.
cv::Mat TalkingHeadFace() {
  cv::VideoCapture video(testing::DataDir() + "/video/talking_d9.mp4");
  cv::Mat frame, face;
  if (video.read(frame)) cv::resize(frame, face, cv::Size(256, 256), 0, 0, cv::INTER_AREA);
  return face;
}

}  // namespace

TEST(LandmarkAgreement, EyeOpeningAndCorrelation) {
  EXPECT_NEAR(EyeOpening(Eyes(9)), 0.3, 1e-12);
  EXPECT_NEAR(EyeOpening(Eyes(0)), 0.0, 1e-12);
  EXPECT_NEAR(PearsonCorrelation({1, 2, 3, 4}, {2, 4, 6, 8}), 1.0, 1e-12);
  EXPECT_NEAR(PearsonCorrelation({1, 2, 3, 4}, {8, 6, 4, 2}), -1.0, 1e-12);
  EXPECT_EQ(PearsonCorrelation({1, 1, 1}, {1, 2, 3}), 0.0);
  EXPECT_EQ(PearsonCorrelation({1, 2}, {1, 2}), 0.0);
}

// A face against itself agrees; against itself shifted by 5 pixels every
// region is off by about 5 pixels over the eye distance. The pictures are
// 256² frames of a talking head, as the avatar's are.
TEST(LandmarkAgreement, ShiftedPictureIsOffByTheShift) {
  HEADCAST_REQUIRE_DATA("video/talking_d9.mp4");
  const std::string predictor = FaceTrackerOptions{}.predictor_path;
  if (!std::filesystem::exists(predictor)) GTEST_SKIP() << "no dlib shape predictor at " << predictor;
  const cv::Mat face = TalkingHeadFace();
  ASSERT_FALSE(face.empty());
  LandmarkAgreement same(predictor);
  same.Add(face, face);
  const nlohmann::json s = same.Summary();
  ASSERT_EQ(s["found_in_both"], 1) << s.dump();
  EXPECT_LT(s["error_iod"]["all"].get<double>(), 1e-9);
  EXPECT_FALSE(s.contains("fit")) << "no fitted landmarks were given";
  cv::Mat shifted;
  cv::warpAffine(face, shifted, cv::Matx23d(1, 0, 5, 0, 1, 0), face.size(), cv::INTER_LINEAR, cv::BORDER_REPLICATE);
  LandmarkAgreement moved(predictor);
  moved.Add(face, shifted);
  moved.Add(face, cv::Mat(face.size(), face.type(), cv::Scalar::all(90)));  // no face: counted, not scored
  const nlohmann::json m = moved.Summary();
  EXPECT_EQ(m["frames"], 2);
  ASSERT_EQ(m["found_in_both"], 1) << m.dump();
  // The eye distance is about 50 px: 5 px is about 0.1.
  for (const char* region : {"eyes", "brows", "nose", "mouth", "jaw"}) {
    const double e = m["error_iod"][region];
    EXPECT_GT(e, 0.04) << region;
    EXPECT_LT(e, 0.2) << region;
  }
}

// With fitted landmarks each picture is also set against the fit: here the
// "fit" is dlib's own points on the true picture, so the truth agrees with it
// and the shifted picture is as far from it as from the truth.
TEST(LandmarkAgreement, EachPictureIsSetAgainstTheFit) {
  HEADCAST_REQUIRE_DATA("video/talking_d9.mp4");
  FaceTrackerOptions options;
  if (!std::filesystem::exists(options.predictor_path))
    GTEST_SKIP() << "no dlib shape predictor at " << options.predictor_path;
  const cv::Mat face = TalkingHeadFace();
  ASSERT_FALSE(face.empty());
  options.redetect_interval = 1;
  options.repair.enabled = false;
  FaceTracker tracker(options);
  const FaceObservation seen = tracker.Track(face, 0);
  ASSERT_NE(seen.status, FaceStatus::kNoFace);
  cv::Mat shifted;
  cv::warpAffine(face, shifted, cv::Matx23d(1, 0, 0, 0, 1, 6), face.size(), cv::INTER_LINEAR, cv::BORDER_REPLICATE);
  LandmarkAgreement agreement(options.predictor_path);
  agreement.Add(face, shifted, &seen.raw);
  const nlohmann::json s = agreement.Summary();
  ASSERT_TRUE(s.contains("fit")) << s.dump();
  EXPECT_EQ(s["fit"]["frames"], 1);
  for (const char* region : {"eyes", "brows", "nose", "mouth", "jaw", "all"}) {
    EXPECT_LT(s["fit"]["truth_vs_fit"][region].get<double>(), 1e-9) << region;
    EXPECT_NEAR(s["fit"]["avatar_vs_fit"][region].get<double>(), s["error_iod"][region].get<double>(), 1e-12) << region;
    EXPECT_GT(s["fit"]["avatar_vs_fit"][region].get<double>(), 0.05) << region;  // 6 px of about 50
    // One frame: its offsets are their own mean, nothing moves.
    EXPECT_LT(s["fit"]["avatar_vs_fit_moving"][region].get<double>(), 1e-9) << region;
  }
  // A second frame, the avatar shifted the other way: against the steady
  // offset (the mean: no shift) each frame's avatar is 6 px off, the truth 0.
  cv::Mat back;
  cv::warpAffine(face, back, cv::Matx23d(1, 0, 0, 0, 1, -6), face.size(), cv::INTER_LINEAR, cv::BORDER_REPLICATE);
  agreement.Add(face, back, &seen.raw);
  const nlohmann::json two = agreement.Summary();
  EXPECT_EQ(two["fit"]["frames"], 2);
  for (const char* region : {"eyes", "brows", "nose", "mouth", "jaw", "all"}) {
    EXPECT_LT(two["fit"]["truth_vs_fit_moving"][region].get<double>(), 1e-9) << region;
    EXPECT_GT(two["fit"]["avatar_vs_fit_moving"][region].get<double>(), 0.05) << region;
    EXPECT_LT(two["fit"]["avatar_vs_fit_moving"][region].get<double>(), 0.25) << region;
  }
}

}  // namespace headcast
