// The camera contract from the avatar to the live tracker: which camera the
// sender tracks with, and the contract read from an avatar's manifest; the
// photometric anchor's references read from it too. The hair's outline cut
// beside the fit.
#include "sender/live_tracker.h"

#include <gtest/gtest.h>

#include "common/core/crop.h"
#include "common/core/zip_archive.h"
#include "common/headmodel/head_outline.h"
#include "common/tracking/head_fitter.h"
#include "tests/testing/resting_head_scenes.h"
#include "tests/testing/test_data.h"

namespace headcast {
namespace {

CameraContract Contract() {
  CameraContract c;
  c.source = PinholeCamera{640, 640, 319.5, 239.5, 640, 480};
  c.crop_x0 = 100;
  c.crop_y0 = 20;
  c.crop_side = 400;
  return c;
}

TEST(CameraContract, ScalesToTheFrameSizeAndRefusesAnotherAspect) {
  const CameraContract c = Contract();
  const std::optional<PinholeCamera> same = ContractCameraFor(c, 640, 480);
  ASSERT_TRUE(same);
  EXPECT_EQ(same->fx, 640);
  const std::optional<PinholeCamera> doubled = ContractCameraFor(c, 1280, 960);
  ASSERT_TRUE(doubled);
  EXPECT_DOUBLE_EQ(doubled->fx, 1280);
  EXPECT_DOUBLE_EQ(doubled->cx, 639.5);  // pixel centres scale with the image
  EXPECT_FALSE(ContractCameraFor(c, 1280, 720));
  const CameraContract back = CameraContract::FromJson(c.ToJson());
  EXPECT_EQ(back.source.width, 640);
  EXPECT_EQ(back.crop_side, 400);
  nlohmann::json bad = c.ToJson();
  bad["crop"]["side"] = -1;
  EXPECT_THROW(CameraContract::FromJson(bad), std::invalid_argument);
  bad = c.ToJson();
  bad.erase("source");
  EXPECT_THROW(CameraContract::FromJson(bad), std::invalid_argument);
}

TEST(CameraContract, TheTrackerPrefersGivenThenCalibratedThenTheAvatarsCamera) {
  LiveTrackerOptions o;
  o.fov_deg = 40;
  EXPECT_EQ(ChooseTrackingCamera(o, std::nullopt, 640, 480).second, "the field of view");
  o.contract = Contract();
  auto [k, why] = ChooseTrackingCamera(o, std::nullopt, 1280, 960);
  EXPECT_EQ(why, "the avatar's training camera");
  EXPECT_DOUBLE_EQ(k.fx, 1280);
  EXPECT_EQ(ChooseTrackingCamera(o, std::nullopt, 1280, 720).second, "the field of view");
  const PinholeCamera stereo{700, 700, 320, 240, 640, 480};
  EXPECT_EQ(ChooseTrackingCamera(o, stereo, 640, 480).second, "the source's calibration");
  o.camera = PinholeCamera{500, 500, 320, 240, 640, 480};
  EXPECT_EQ(ChooseTrackingCamera(o, stereo, 640, 480).second, "given intrinsics");
}

TEST(CameraContract, ReadFromTheAvatarsManifest) {
  const std::string dir = testing::TempDir("camera_contract");
  const nlohmann::json manifest = {{"format", "headcast-avatar"}, {"camera", Contract().ToJson()}};
  WriteZip(dir + "/a.hcavatar", {{"manifest.json", manifest.dump()}});
  const std::optional<CameraContract> c = ReadAvatarCameraContract(dir + "/a.hcavatar");
  ASSERT_TRUE(c);
  EXPECT_EQ(c->crop_x0, 100);
  WriteZip(dir + "/old.hcavatar", {{"manifest.json", nlohmann::json{{"format", "headcast-avatar"}}.dump()}});
  EXPECT_FALSE(ReadAvatarCameraContract(dir + "/old.hcavatar"));
  EXPECT_FALSE(ReadAvatarCameraContract(dir + "/params.json"));  // not an avatar: no contract
  nlohmann::json broken = manifest;
  broken["camera"]["source"]["fx"] = -5;
  WriteZip(dir + "/broken.hcavatar", {{"manifest.json", broken.dump()}});
  try {
    ReadAvatarCameraContract(dir + "/broken.hcavatar");
    ADD_FAILURE() << "a negative focal length was accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("broken.hcavatar"), std::string::npos);
  }
}

TEST(AnchorReference, ReadFromTheAvatarsManifest) {
  const std::string dir = testing::TempDir("anchor_reference");
  AnchorReference r;
  r.options.weight = 0.5;
  r.options.points = 20;
  r.grey.assign(20, 0.4);
  const nlohmann::json manifest = {{"format", "headcast-avatar"}, {"tracking_anchor", r.ToJson()}};
  WriteZip(dir + "/a.hcavatar", {{"manifest.json", manifest.dump()}});
  const std::optional<AnchorReference> read = ReadAvatarAnchorReference(dir + "/a.hcavatar");
  ASSERT_TRUE(read);
  EXPECT_EQ(read->referenced(), 20);
  EXPECT_EQ(read->options.weight, 0.5);
  WriteZip(dir + "/old.hcavatar", {{"manifest.json", nlohmann::json{{"format", "headcast-avatar"}}.dump()}});
  EXPECT_FALSE(ReadAvatarAnchorReference(dir + "/old.hcavatar"));
  EXPECT_FALSE(ReadAvatarAnchorReference(dir + "/params.json"));  // not an avatar: none
  nlohmann::json broken = manifest;
  broken["tracking_anchor"]["grey"][0] = -0.2;
  WriteZip(dir + "/broken.hcavatar", {{"manifest.json", broken.dump()}});
  try {
    ReadAvatarAnchorReference(dir + "/broken.hcavatar");
    ADD_FAILURE() << "a negative grey level was accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("broken.hcavatar"), std::string::npos);
  }
}

// The renders' square, as an avatar's camera contract would give it.
FrameCrop SceneCrop(const testing::RestingHeadScenes& scenes) {
  CameraContract contract;
  contract.source = scenes.camera();
  contract.crop_x0 = 120;
  contract.crop_y0 = 40;
  contract.crop_side = 400;
  return *ContractCrop(contract, scenes.camera(), 256);
}

std::vector<float> TrueOutline(const testing::RestingHeadScenes::Scene& s, const FrameCrop& crop) {
  cv::Mat truth = CropSquare(s.mask, crop.x0, crop.y0, crop.side, crop.resolution, cv::INTER_LINEAR);
  cv::threshold(truth, truth, 127, 255, cv::THRESH_BINARY);
  const OutlineOptions o;
  return MeasureOutline(truth, OutlineFrame::Of(crop.camera, s.params.CamFromHead(), o), o);
}

// The scenes, their square and what a fit of them gives.
struct OutlinerScenes : testing::RestingHeadScenes {
  OutlinerScenes() : RestingHeadScenes(9) {}
  const FrameCrop crop = SceneCrop(*this);
  const HeadFitter fitter{model()};
  const Eigen::VectorXd identity = Eigen::VectorXd::Zero(model().num_shape());
};

// The head mask cut on worker threads while the tracker fits (its colour
// models learnt anew on a second one) gives the outline the tracking thread's
// own cut gives, and both are the head's, over a turning head; with the cuts
// between learnings kept near the last outline (band) too.
TEST(FrameOutliner, BesideTheFitMeasuresWhatTheTrackingThreadWould) {
  const OutlinerScenes scenes;
  for (int band : {0, 8}) {
    cv::theRNG() = cv::RNG();  // a learning's k-means++ draws from it: as the outliner's new threads start
    HeadMaskOptions mask;
    mask.refit_every = 3;
    mask.band = band;
    FrameOutliner beside(scenes.model(), scenes.crop, MatteRules{}, mask),
        after(scenes.model(), scenes.crop, MatteRules{}, mask, false);
    int known = 0;
    for (int i = 0; i < 7; ++i) {
      const testing::RestingHeadScenes::Scene s = scenes.At(0.7, -6 + 2 * i, 5);
      beside.Start(s.image, s.landmarks);
      after.Start(s.image, s.landmarks);
      const Landmarks2d fitted = scenes.fitter.Project(s.params, scenes.crop.camera);
      const std::vector<float> a = beside.Finish(s.params, fitted, scenes.identity),
                               b = after.Finish(s.params, fitted, scenes.identity), truth = TrueOutline(s, scenes.crop);
      ASSERT_EQ(a.size(), truth.size());
      ASSERT_EQ(b.size(), truth.size());
      for (size_t k = 0; k < truth.size(); ++k) {
        if (truth[k] == kOutlineUnknown) continue;
        ++known;
        EXPECT_NEAR(a[k], truth[k], 3.0) << "band " << band << " frame " << i << " arc " << k;
        EXPECT_NEAR(b[k], truth[k], 3.0) << "band " << band << " frame " << i << " arc " << k;
        EXPECT_NEAR(a[k], b[k], 2.0) << "band " << band << " frame " << i << " arc " << k;
      }
    }
    EXPECT_GE(known, 7 * 6);
  }
}

// A frame whose mask cannot be cut goes without an outline and the next one is
// measured; a frame not fitted is dropped; Finish needs a Start.
TEST(FrameOutliner, AFrameItCannotCutGoesWithoutOne) {
  const OutlinerScenes scenes;
  HeadMaskOptions mask;
  mask.refit_every = 4;
  for (bool beside_fit : {true, false}) {
    FrameOutliner outliner(scenes.model(), scenes.crop, MatteRules{}, mask, beside_fit);
    const testing::RestingHeadScenes::Scene s = scenes.At(0.7, 0, 0);
    const Landmarks2d fitted = scenes.fitter.Project(s.params, scenes.crop.camera);
    Landmarks2d broken = s.landmarks;
    broken[5].x() = NAN;
    outliner.Start(s.image, broken);
    EXPECT_THROW(outliner.Finish(s.params, fitted, scenes.identity), std::invalid_argument);
    EXPECT_THROW(outliner.Finish(s.params, fitted, scenes.identity), std::logic_error);  // no frame started
    outliner.Start(s.image, s.landmarks);
    outliner.Abandon();
    outliner.Start(s.image, s.landmarks);
    outliner.Forget();
    outliner.Start(s.image, s.landmarks);
    const std::vector<float> outline = outliner.Finish(s.params, fitted, scenes.identity),
                             truth = TrueOutline(s, scenes.crop);
    int known = 0;
    for (size_t k = 0; k < truth.size(); ++k)
      if (truth[k] != kOutlineUnknown) {
        ++known;
        EXPECT_NEAR(outline[k], truth[k], 3.0) << "arc " << k;
      }
    EXPECT_GE(known, 6);
  }
  HeadMaskOptions bad;
  bad.refit_every = 0;
  EXPECT_THROW(FrameOutliner(scenes.model(), scenes.crop, MatteRules{}, bad), std::invalid_argument);
}

}  // namespace
}  // namespace headcast
