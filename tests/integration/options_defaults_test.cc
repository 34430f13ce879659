// Every options struct's defaults pass its Check(). Structs with fields a
// user must give (an input, a token, TLS files) pass once exactly those are
// set, and without them they fail naming the field.
#include <gtest/gtest.h>

#include <functional>
#include <string>
#include <vector>

#include "common/avatar/avatar_backend.h"
#include "common/avatar/avatar_config.h"
#include "common/capture/frame_source.h"
#include "common/capture/stereo_depth.h"
#include "common/headmodel/builtin_head.h"
#include "common/headmodel/head_render.h"
#include "common/headmodel/ict_converter.h"
#include "common/headmodel/synthetic_motion.h"
#include "common/raster/rasterizer.h"
#include "common/tracking/appearance_fit.h"
#include "common/tracking/head_mask.h"
#include "common/tracking/mesh_fitter.h"
#include "common/tracking/offline_tracker.h"
#include "common/tracking/outline_hold.h"
#include "common/tracking/rgbd_fitter.h"
#include "common/tracking/synthetic_scan.h"
#include "receiver/display/display.h"
#include "receiver/jitter_buffer.h"
#include "receiver/render_loop.h"
#include "receiver/session_server.h"
#include "sender/session_client.h"
#include "training/create.h"
#include "training/data_parallel.h"
#include "training/dataset.h"
#include "training/guided_recording.h"
#include "training/refine_options.h"
#include "training/runs.h"
#include "training/synthetic_data.h"

namespace headcast {
namespace {

struct Case {
  std::string name;
  std::function<void()> defaults_check;  // Check() on the defaults (with the required fields set)
  std::string required;                  // what the defaults alone lack ("" when nothing)
  std::function<void()> bare_check;      // Check() on the plain defaults, when `required` is set
};

template <typename T>
Case Plain(const std::string& name) {
  return {name, [] { T().Check(); }, "", nullptr};
}

template <typename T>
Case Needs(const std::string& name, const std::string& required, std::function<void(T*)> set) {
  return {name,
          [set] {
            T o;
            set(&o);
            o.Check();
          },
          required, [] { T().Check(); }};
}

std::vector<Case> Cases() {
  return {
      Plain<AvatarConfig>("AvatarConfig"),
      Plain<AvatarBackendOptions>("AvatarBackendOptions"),
      Plain<RasterOptions>("RasterOptions"),
      Plain<SyntheticMotionOptions>("SyntheticMotionOptions"),
      Plain<BuiltinHeadOptions>("BuiltinHeadOptions"),
      Plain<HeadRenderOptions>("HeadRenderOptions"),
      Needs<IctConvertOptions>("IctConvertOptions", "folder", [](IctConvertOptions* o) { o->folder = "ict"; }),
      Plain<StereoMatchOptions>("StereoMatchOptions"),
      Plain<SourceOptions>("SourceOptions"),
      Needs<OfflineTrackOptions>("OfflineTrackOptions", "input", [](OfflineTrackOptions* o) { o->input = "clip.mp4"; }),
      Plain<AppearanceFitOptions>("AppearanceFitOptions"),
      Plain<SyntheticScanOptions>("SyntheticScanOptions"),
      Plain<FaceTrackerOptions>("FaceTrackerOptions"),
      Plain<HeadFitterOptions>("HeadFitterOptions"),
      Plain<RgbdFitOptions>("RgbdFitOptions"),
      Plain<FrameTrackerOptions>("FrameTrackerOptions"),
      Plain<MeshFitOptions>("MeshFitOptions"),
      Plain<BlackBoxFitOptions>("BlackBoxFitOptions"),
      Plain<HeadMaskOptions>("HeadMaskOptions"),
      Plain<OutlineHoldOptions>("OutlineHoldOptions"),
      Plain<PinholeCamera>("PinholeCamera"),
      Plain<DisplayOptions>("DisplayOptions"),
      Plain<JitterBufferOptions>("JitterBufferOptions"),
      Plain<RenderLoopOptions>("RenderLoopOptions"),
      Needs<ReceiverSessionOptions>("ReceiverSessionOptions", "tokens",
                                    [](ReceiverSessionOptions* o) { o->tokens = {"t"}; }),
      Needs<ReceiverServerOptions>("ReceiverServerOptions", "tls_cert",
                                   [](ReceiverServerOptions* o) {
                                     o->tokens = {"t"};
                                     o->tls_cert = "/dev/null";  // Check reads nothing, but wants readable files
                                     o->tls_key = "/dev/null";
                                   }),
      Needs<SenderOptions>("SenderOptions", "tls_ca", [](SenderOptions* o) { o->tls_ca = "/dev/null"; }),
      Needs<PrepOptions>("PrepOptions", "input",
                         [](PrepOptions* o) {
                           o->input = "clip.mp4";
                           o->out_dir = "dataset";
                         }),
      Plain<DistributedOptions>("DistributedOptions"),
      Plain<MixSchedule>("MixSchedule"),
      Plain<LossOptions>("LossOptions"),
      Plain<FitOptions>("FitOptions"),
      Plain<RefineOptions>("RefineOptions"),
      Needs<PretrainOptions>("PretrainOptions", "out", [](PretrainOptions* o) { o->outputs.out = "general.hcavatar"; }),
      Needs<SubjectOptions>("SubjectOptions", "dataset",
                            [](SubjectOptions* o) {
                              o->general = "general.hcavatar";
                              o->dataset = "dataset";
                              o->outputs.out = "me.hcavatar";
                            }),
      Needs<EvalOptions>("EvalOptions", "avatar",
                         [](EvalOptions* o) {
                           o->avatar = "me.hcavatar";
                           o->dataset = "dataset";
                           o->out_dir = "eval";
                         }),
      Plain<SyntheticDataOptions>("SyntheticDataOptions"),
      Needs<CreateOptions>("CreateOptions", "input",
                           [](CreateOptions* o) {
                             o->input = "me.mp4";
                             o->out = "me.hcavatar";
                           }),
      Needs<GuidedRecordingOptions>("GuidedRecordingOptions", "out_dir",
                                    [](GuidedRecordingOptions* o) { o->out_dir = "recording"; }),
  };
}

TEST(OptionsDefaults, EveryOptionsStructsDefaultsPassCheck) {
  for (const Case& c : Cases()) {
    EXPECT_NO_THROW(c.defaults_check()) << c.name;
    if (c.required.empty()) continue;
    try {
      c.bare_check();
      ADD_FAILURE() << c.name << ": defaults without " << c.required << " should be refused";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(c.required), std::string::npos) << c.name << ": " << e.what();
    }
  }
}

}  // namespace
}  // namespace headcast
