// Avatar: one person's neural avatar (config, subject parameters, network
// weights) and its file, `.hcavatar` (DESIGN "Contracts"): a zip holding
// manifest.json (format version, network config, output resolution, head-model
// fingerprint, training summary, subject parameters), weights.pt and preview.png.
#pragma once

#include <memory>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <optional>
#include <string>

#include "common/avatar/avatar_config.h"
#include "common/headmodel/head_model.h"
#include "common/headmodel/params.h"

namespace headcast {

constexpr int kAvatarFormatVersion = 1;
struct AvatarModules;  // the libtorch networks, common/avatar/avatar_model.h

// Subject parameters for a model when nothing better is known: neutral shape
// and texture, the default light, a 24-degree camera at the output size.
SubjectParams DefaultSubject(const HeadModel& model, int output_size);

// `config` with its conditioning sizes (beta, psi, tau components) cut to what `model` has.
AvatarConfig FitConfigToModel(AvatarConfig config, const HeadModel& model);

class Avatar {
 public:
  // Randomly initialised networks (tests, benchmarks); deterministic for a seed.
  // The conditioning sizes are cut to the model's (FitConfigToModel).
  static Avatar CreateRandom(const AvatarConfig& config, const HeadModel& model, const SubjectParams& subject,
                             uint64_t seed = 1);
  // Refuses, with a message naming the file, anything that is not an avatar of
  // this format version for this head model: missing, truncated or foreign
  // files, other versions, another head model's fingerprint, mismatched weights.
  static Avatar Load(const std::string& path, const HeadModel& model);
  // Atomic (temporary file + rename). `preview_bgr` may be empty.
  void Save(const std::string& path, const cv::Mat& preview_bgr = cv::Mat()) const;
  // The manifest of a file without loading the weights (for `info`).
  static nlohmann::json ReadManifest(const std::string& path);

  // A copy whose run-time switches (sampling, samples per ray, shell, precompute)
  // and output size come from `config`; the architecture must be the same
  // (throws otherwise). The networks do not depend on the output size (CNeRF
  // works in the head's frame, the renderer is convolutional), so a general
  // model trained at 128 can be fine-tuned at 256.
  Avatar WithRuntimeSwitches(const AvatarConfig& config) const;

  Avatar(Avatar&&) noexcept;
  Avatar& operator=(Avatar&&) noexcept;
  ~Avatar();

  const AvatarConfig& config() const;
  const SubjectParams& subject() const;
  SubjectParams& mutable_subject();
  const std::string& head_model_fingerprint() const;
  // The camera and crop the avatar was trained with (nothing for avatars not
  // trained on a prepared video: general models, older files).
  const std::optional<CameraContract>& camera_contract() const;
  void set_camera_contract(const CameraContract& contract);
  // What the tracker held the head's placement to in the training frames (the
  // photometric anchor's references, tracking's AnchorReference as JSON; null:
  // none). Carried, not read, here: the sender reads it so that it tracks by
  // the rule the avatar was trained with (ReadAvatarAnchorReference).
  const nlohmann::json& tracking_anchor() const;
  void set_tracking_anchor(const nlohmann::json& reference);
  // How the training frames' expressions were fitted (tracking's
  // ExpressionFitSettings as JSON; null: none, a file from before). Carried
  // for the sender, which fits live frames the same way (ReadAvatarExpressionFit).
  const nlohmann::json& tracking_fit() const;
  void set_tracking_fit(const nlohmann::json& settings);
  nlohmann::json& training_summary();
  const nlohmann::json& training_summary() const;
  AvatarModules& modules();
  const AvatarModules& modules() const;

 private:
  Avatar();
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace headcast
