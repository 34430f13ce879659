// The trainer: samples, losses, the optimiser loop, checkpoints, evaluation.
#include "training/avatar_fit.h"

#include <spdlog/spdlog.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <numeric>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <random>

#include "common/avatar/avatar_pipeline.h"
#include "common/avatar/compute_threads.h"
#include "common/core/options.h"
#include "common/core/timer.h"
#include "common/core/zip_archive.h"
#include "common/headmodel/head_render.h"
#include "training/face_regions.h"
#include "training/image_losses.h"

namespace headcast {

double MixSchedule::SyntheticProbability(int step) const {
  if (step <= m) return 1.0;
  if (step >= n_end) return p_min;
  return (1.0 - static_cast<double>(step - m) / (n_end - m)) * (p_max - p_min) + p_min;
}

void MixSchedule::Check() const {
  OptionsCheck c("MixSchedule");
  c.NonNegative("m", m).That(n_end > m, "n_end must be > m");
  c.InRange("p_min", p_min, 0.0, 1.0).InRange("p_max", p_max, 0.0, 1.0).That(p_max >= p_min, "p_max must be >= p_min");
  c.ThrowIfErrors();
}

void LossOptions::Check() const {
  OptionsCheck c("LossOptions");
  c.NonNegative("mse_weight", mse_weight).NonNegative("perceptual_weight", perceptual_weight);
  c.NonNegative("ssim_weight", ssim_weight).NonNegative("offset_weight", offset_weight);
  c.NonNegative("matte_weight", matte_weight).NonNegative("frame_shift_weight", frame_shift_weight);
  c.ThrowIfErrors();
  regions.Check();
}

void FitOptions::Check() const {
  OptionsCheck c("FitOptions");
  c.InRange("iterations", iterations, 0, 100000000)
      .InRange("batch", batch, 1, 4096)
      .Positive("learning_rate", learning_rate)
      .InRange("final_lr_fraction", final_lr_fraction, 1e-4, 1.0)
      .InRange("warmup_steps", warmup_steps, 0, 100000000)
      .InRange("surface_lr_scale", surface_lr_scale, 0.0, 1000.0)
      .InRange("blend_lr_scale", blend_lr_scale, 0.0, 1000.0)
      .InRange("offset_lr_scale", offset_lr_scale, 0.0, 1000.0)
      .InRange("offset_segment", offset_segment, 1, 100000)
      .InRange("frame_shift_rate", frame_shift_rate, 0.0, 10.0)
      .InRange("exposure_rate", exposure_rate, 0.0, 1.0)
      .That(blend_decay >= 0 && blend_decay * learning_rate * blend_lr_scale < 1,
            "blend_decay is >= 0 and shrinks the blendshapes by less than all of them a step "
            "(blend_decay * learning_rate * blend_lr_scale < 1)")
      .That(weight_average == 0 || (weight_average > 0 && weight_average < 1),
            "weight_average is 0 (off) or a decay in (0, 1)")
      .InRange("checkpoint_every", checkpoint_every, 1, 100000000)
      .InRange("freeze_cnerf_layers", freeze_cnerf_layers, 0, 64)
      .InRange("expression_noise", expression_noise, 0.0, 10.0)
      .InRange("anchor_weight", anchor_weight, 0.0, 1000.0)
      .InRange("z_augmentation", z_augmentation, 0.0, 1.0)
      .InRange("z_scale_min", z_scale_min, 0.3, 1.0)
      .InRange("z_scale_max", z_scale_max, 1.0, 3.0)
      .InRange("roll_augmentation", roll_augmentation, 0.0, 1.0)
      .InRange("roll_max_degrees", roll_max_degrees, 0.0, 90.0)
      .InRange("threads", threads, 0, 256);
  c.That(!resume || !checkpoint_dir.empty(), "resume needs a checkpoint_dir");
  c.ThrowIfErrors();
  loss.Check();
  mix.Check();
  rare_expressions.Check();
  distributed.Check();
}

double FitOptions::LearningRateAt(int step) const {
  const double warmup = step < warmup_steps ? (step + 1.0) / warmup_steps : 1.0;
  if (iterations <= 1) return learning_rate * warmup;
  return learning_rate * warmup * std::pow(final_lr_fraction, static_cast<double>(step) / (iterations - 1));
}

double FitOptions::WeightAverageDecayAt(int step) const {
  return std::min(weight_average, (1.0 + step) / (10.0 + step));
}

double SubjectWeightAverage(int iterations) { return iterations < 9 ? 0.0 : std::min(0.999, 1.0 - 8.0 / iterations); }

namespace {

// A real frame's picture and mask moved by `affine` (source to destination
// pixels): the image interpolated, the mask kept binary; what comes in at the
// edges is background.
void WarpFrame(const cv::Matx23d& affine, cv::Mat* image, cv::Mat* mask) {
  cv::Mat warped_image, warped_mask;
  cv::warpAffine(*image, warped_image, affine, image->size(), cv::INTER_LINEAR, cv::BORDER_CONSTANT);
  cv::warpAffine(*mask, warped_mask, affine, mask->size(), cv::INTER_NEAREST, cv::BORDER_CONSTANT);
  *image = warped_image;
  *mask = warped_mask;
}

}  // namespace

void TurnCamera(double angle, const PinholeCamera& camera, FrameParams* frame, cv::Mat* image, cv::Mat* mask) {
  const double c = std::cos(angle), s = std::sin(angle);
  // Camera points turn by Rz(angle); in pixels that is K Rz K^-1, a rotation
  // about the principal point when the focal lengths are equal.
  const double a = c, b = -s * camera.fx / camera.fy, d = s * camera.fy / camera.fx;
  const cv::Matx23d affine(a, b, camera.cx - a * camera.cx - b * camera.cy, d, c,
                           camera.cy - d * camera.cx - c * camera.cy);
  WarpFrame(affine, image, mask);
  RigidTransform turn;
  turn.rotation << c, -s, 0, s, c, 0, 0, 0, 1;
  frame->SetCamFromHead(turn * frame->CamFromHead());
}

cv::Mat MaskedTarget(const cv::Mat& image_bgr, const cv::Mat& mask) {
  const cv::Vec3f rgb = HeadRenderOptions{}.background_rgb;
  cv::Mat out(image_bgr.size(), CV_8UC3,
              cv::Scalar(std::lround(255 * rgb[2]), std::lround(255 * rgb[1]), std::lround(255 * rgb[0])));
  image_bgr.copyTo(out, mask);
  return out;
}

namespace {

// A training sample: the frame through the one preparation path, and its target.
struct PreparedSample {
  AvatarFrameInputs inputs;
  torch::Tensor target;  // (1, 3, R, R): the picture masked onto the background colour
  torch::Tensor mask;    // (1, 1, R, R) in {0, 1}
  torch::Tensor weight;  // (1, 1, R, R) per-pixel weight of the MSE; undefined: all ones
  torch::Tensor blind;   // (1, 1, R, R) bool: pixels the loss ignores; undefined: none
};

// With a bounded matte the mask is cut to the bound too: a synthetic render
// shows the neck, which an avatar bounded at the jaw line cannot.
PreparedSample Prepare(const AvatarConfig& config, const HeadModel& model, const SubjectParams& subject,
                       const FrameParams& frame, const cv::Mat& image_bgr, const cv::Mat& mask, RaySampler* sampler,
                       const FaceRegionOptions& regions, bool blind_regions, std::mt19937* rng) {
  PreparedSample p;
  PrepareAvatarFrame(config, model, model.MakeIdentity(subject.shape.cast<double>()), subject, frame, sampler, rng,
                     &p.inputs);
  if (regions.weight > 0 || blind_regions) {
    const Landmarks2d landmarks = ProjectLandmarks(p.inputs.posed, p.inputs.cam_from_head, subject.intrinsics);
    if (regions.weight > 0) {
      const cv::Mat w = FaceRegionWeights(landmarks, image_bgr.size(), regions);
      p.weight = torch::from_blob(w.data, {1, 1, w.rows, w.cols}, torch::kFloat).clone();
    }
    if (blind_regions) {
      const cv::Mat b = FaceRegionMask(landmarks, image_bgr.size(), regions);
      p.blind = torch::from_blob(b.data, {1, 1, b.rows, b.cols}, torch::kUInt8).gt(127);
    }
  }
  cv::Mat m = mask;
  if (!p.inputs.matte_bound.empty()) cv::bitwise_and(mask, p.inputs.matte_bound, m);
  p.target = BgrToImageTensor(MaskedTarget(image_bgr, m));
  const cv::Mat contiguous = m.isContinuous() ? m : m.clone();
  p.mask = torch::from_blob(contiguous.data, {1, 1, m.rows, m.cols}, torch::kUInt8).gt(127).to(torch::kFloat);
  return p;
}

// METHOD §5's z-augmentation: the head moved along its line of sight by 1/scale
// looks (nearly) the same picture scaled by `scale` about the head's centre.
void ChangeDistance(double scale, const PinholeCamera& camera, FrameParams* frame, cv::Mat* image, cv::Mat* mask) {
  const Eigen::Vector2d c = camera.Project(frame->cam_translation.cast<double>());
  const cv::Matx23d affine(scale, 0, (1 - scale) * c.x(), 0, scale, (1 - scale) * c.y());
  WarpFrame(affine, image, mask);
  frame->cam_translation /= static_cast<float>(scale);
}

// Per-frame learnable offsets of the real frames' conditioning (METHOD eq. 8).
struct Offsets {
  torch::Tensor geometry, appearance;            // (frames, D), trained
  torch::Tensor geometry_mask, appearance_mask;  // (1, D), 0 where frozen (beta, tau in a fine-tune)
  bool enabled() const { return geometry.defined(); }
};

Offsets MakeOffsets(const AvatarConfig& config, int frames, bool freeze_identity, bool identity_offsets) {
  Offsets o;
  o.geometry = torch::zeros({frames, config.conditioning_dim()}, torch::requires_grad());
  o.appearance = torch::zeros({frames, config.appearance_dim()}, torch::requires_grad());
  const ConditioningMasks masks = OffsetMasks(config, freeze_identity);
  if (identity_offsets) masks.geometry.narrow(1, 0, config.num_shape).fill_(1);
  o.geometry_mask = masks.geometry;
  o.appearance_mask = masks.appearance;
  return o;
}

// The moving average of the weights (FitOptions::weight_average) and the
// swap that puts it into the avatar: Tensor::set_data exchanges storages, so
// a swap copies nothing and the optimiser's state stays keyed to the same
// parameters.
class WeightAverage {
 public:
  explicit WeightAverage(const std::vector<torch::Tensor>& params) : params_(params) {
    torch::NoGradGuard no_grad;
    for (const auto& p : params_) average_.push_back(p.detach().clone());
  }
  void Update(double decay) {
    torch::NoGradGuard no_grad;
    for (size_t i = 0; i < params_.size(); ++i) average_[i].mul_(decay).add_(params_[i].detach(), 1 - decay);
  }
  void Swap() {
    for (size_t i = 0; i < params_.size(); ++i) {
      torch::Tensor live = params_[i].detach();  // keeps the live storage
      params_[i].set_data(average_[i]);
      average_[i] = live;
    }
  }
  const std::vector<torch::Tensor>& average() const { return average_; }  // between swaps

 private:
  std::vector<torch::Tensor> params_, average_;
};

// The real training frames of every dataset as one list: where each is
// (dataset, position) and its row among the per-frame offsets (the datasets'
// frames one after another, `segment` consecutive positions to a row, so a
// checkpoint's offsets are for these datasets in this order).
class RealFrames {
 public:
  struct Frame {
    const PreparedDataset* data;
    int position;
    int offset_row;
  };
  RealFrames(const std::vector<const PreparedDataset*>& datasets, int resolution, int segment) {
    for (size_t d = 0; d < datasets.size(); ++d) {
      const std::string which = datasets.size() == 1 ? "the dataset" : "dataset " + std::to_string(d + 1);
      if (!datasets[d]) throw std::invalid_argument("TrainAvatar: " + which + " is missing (null)");
      const PreparedDataset& data = *datasets[d];
      if (data.train().empty()) throw std::invalid_argument("TrainAvatar: " + which + " has no training frames");
      if (data.resolution() != resolution)
        throw std::invalid_argument("TrainAvatar: " + which + "'s crops are " + std::to_string(data.resolution()) +
                                    " pixels, the avatar renders " + std::to_string(resolution));
      for (int i : data.train()) frames_.push_back({&data, i, rows_ + i / segment});
      rows_ += (data.size() + segment - 1) / segment;
    }
  }
  bool empty() const { return frames_.empty(); }
  const std::vector<Frame>& frames() const { return frames_; }
  int offset_rows() const { return rows_; }

 private:
  std::vector<Frame> frames_;
  int rows_ = 0;
};

// Each real frame's image motion since the frame before it, for
// AvatarConfig::motion_blur: from the fitted parameters of the two (the
// frame before is the one with the previous sequence number; interpolated
// frames have none), computed when a frame is first drawn.
class FrameMotions {
 public:
  explicit FrameMotions(const HeadModel& model) : model_(model) {}

  std::optional<ImageMotion> At(const PreparedDataset& data, int position) {
    const auto key = std::make_pair(&data, position);
    if (const auto it = motions_.find(key); it != motions_.end()) return it->second;
    const int real = data.size() - data.interpolated();
    std::optional<ImageMotion> motion;
    if (position < real) {
      auto [known, fresh] = before_.try_emplace(&data);
      if (fresh)
        for (int i = 0; i < real; ++i) known->second.emplace(data.params(i).sequence, i);
      const FrameParams& now = data.params(position);
      const auto before = known->second.find(now.sequence - 1);
      if (now.sequence > 0 && before != known->second.end()) {
        const HeadIdentity identity = model_.MakeIdentity(data.subject().shape.cast<double>());
        motion = MeasureImageMotion(InCamera(identity, data.params(before->second)), InCamera(identity, now),
                                    data.subject().intrinsics);
      }
    }
    return motions_[key] = motion;
  }

 private:
  RasterVertices InCamera(const HeadIdentity& identity, const FrameParams& frame) const {
    HeadModelOutput posed;
    model_.Forward(identity, frame.expression.cast<double>(), frame.HeadPose(), &posed);
    RasterVertices v_cam;
    TransformToCamera(posed.vertices, frame.CamFromHead(), &v_cam);
    return v_cam;
  }

  const HeadModel& model_;
  std::map<std::pair<const PreparedDataset*, int>, std::optional<ImageMotion>> motions_;
  std::map<const PreparedDataset*, std::map<uint64_t, int>> before_;  // sequence -> position
};

// Each sample's draws (synthetic or real, which frame, augmentation, ray
// jitter) from its own generator: a resumed run, or one split over ranks,
// makes exactly the draws of one uninterrupted process.
std::mt19937 SampleRng(uint64_t seed, int step, int b) {
  std::seed_seq seq{static_cast<uint32_t>(seed), static_cast<uint32_t>(seed >> 32), static_cast<uint32_t>(step),
                    static_cast<uint32_t>(b)};
  return std::mt19937(seq);
}

namespace fs = std::filesystem;

void SaveCheckpoint(const fs::path& dir, int next_step, const Avatar& avatar, torch::optim::Adam& adam,
                    const Offsets& offsets, const torch::Tensor& shifts, const torch::Tensor& exposure,
                    WeightAverage* average) {
  const fs::path staging = dir / ("staging-" + std::to_string(next_step));
  fs::remove_all(staging);
  fs::create_directories(staging);
  avatar.Save((staging / "avatar.hcavatar").string());
  torch::serialize::OutputArchive archive;
  adam.save(archive);
  archive.save_to((staging / "optimizer.pt").string());
  if (offsets.enabled())
    torch::save(std::vector<torch::Tensor>{offsets.geometry, offsets.appearance}, (staging / "offsets.pt").string());
  if (shifts.defined()) torch::save(std::vector<torch::Tensor>{shifts}, (staging / "shifts.pt").string());
  if (exposure.defined()) torch::save(std::vector<torch::Tensor>{exposure}, (staging / "exposure.pt").string());
  if (average) torch::save(average->average(), (staging / "average.pt").string());
  WriteFileAtomically((staging / "state.json").string(), nlohmann::json{{"next_step", next_step}}.dump() + "\n");
  // Everything on the disk before the checkpoint is named; the previous one
  // goes only once LATEST names the new one durably.
  for (const auto& entry : fs::directory_iterator(staging)) SyncToDisk(entry.path().string());
  SyncToDisk(staging.string());
  const fs::path final_dir = dir / ("step-" + std::to_string(next_step));
  fs::remove_all(final_dir);
  fs::rename(staging, final_dir);
  SyncToDisk(dir.string());
  std::string previous;
  if (std::ifstream latest(dir / "LATEST"); latest) std::getline(latest, previous);
  WriteFileAtomically((dir / "LATEST").string(), final_dir.filename().string() + "\n");
  if (!previous.empty() && previous != final_dir.filename().string()) fs::remove_all(dir / previous);
}

// A checkpoint folder is continued on purpose or not at all: without
// --resume, an earlier run's checkpoint is not overwritten; with it, a folder
// that does not exist is a typo, not a fresh start.
void CheckCheckpointFolder(const fs::path& dir, bool resume) {
  const bool has_checkpoint = fs::exists(dir / "LATEST");
  if (!resume && has_checkpoint)
    throw std::runtime_error(dir.string() +
                             " holds a checkpoint of an earlier run: --resume continues it; to start afresh, remove "
                             "the folder or choose another --checkpoint-dir");
  if (resume && !fs::is_directory(dir)) throw std::runtime_error("--resume: no checkpoint folder " + dir.string());
  if (resume && !has_checkpoint) spdlog::warn("--resume: no checkpoint in {} yet; starting at step 0", dir.string());
}

// Copies `from` into `to` (same count and shapes, else throws `mismatch`).
void CopyInto(const std::vector<torch::Tensor>& from, const std::vector<torch::Tensor>& to, const char* mismatch) {
  bool fits = from.size() == to.size();
  for (size_t i = 0; fits && i < to.size(); ++i) fits = from[i].sizes().equals(to[i].sizes());
  if (!fits) throw std::runtime_error(mismatch);
  for (size_t i = 0; i < to.size(); ++i) to[i].copy_(from[i]);
}

// Restores weights and optimiser state; returns the step to continue from (0 without a checkpoint).
int LoadCheckpoint(const fs::path& dir, Avatar& avatar, const HeadModel& model, torch::optim::Adam& adam,
                   Offsets* offsets, const torch::Tensor& shifts, const torch::Tensor& exposure,
                   WeightAverage* average) {
  std::ifstream latest(dir / "LATEST");
  if (!latest) return 0;
  std::string name;
  std::getline(latest, name);
  const fs::path ckpt = dir / name;
  try {
    const nlohmann::json state = nlohmann::json::parse(std::ifstream(ckpt / "state.json"));
    const int next_step = state.at("next_step").get<int>();
    const Avatar saved = Avatar::Load((ckpt / "avatar.hcavatar").string(), model);
    const std::vector<torch::Tensor> to = avatar.modules().parameters();
    torch::NoGradGuard no_grad;
    CopyInto(saved.modules().parameters(), to, "the checkpoint's networks differ from this avatar's");
    auto load = [&](const char* file) {
      std::vector<torch::Tensor> tensors;
      torch::load(tensors, (ckpt / file).string());
      return tensors;
    };
    if (offsets->enabled())
      CopyInto(load("offsets.pt"), {offsets->geometry, offsets->appearance},
               "the checkpoint's per-frame offsets are for another dataset");
    if (shifts.defined())
      CopyInto(load("shifts.pt"), {shifts}, "the checkpoint's per-frame shifts are for another dataset");
    if (exposure.defined()) {
      if (!fs::exists(ckpt / "exposure.pt"))
        throw std::runtime_error("the checkpoint was made without motion blur (no exposure.pt)");
      CopyInto(load("exposure.pt"), {exposure}, "the checkpoint's exposure is not one value");
    }
    if (average)  // a checkpoint made without averaging starts the average at its weights
      CopyInto(fs::exists(ckpt / "average.pt") ? load("average.pt") : to, average->average(),
               "the checkpoint's averaged weights differ from this avatar's networks");
    torch::serialize::InputArchive archive;
    archive.load_from((ckpt / "optimizer.pt").string());
    adam.load(archive);
    return next_step;
  } catch (const std::exception& e) {
    throw std::runtime_error(ckpt.string() + ": cannot resume from this checkpoint (" + e.what() + ")");
  }
}

// The texture's and its blendshapes' root-mean-square texel values, and the
// rows (expression coefficients or principal directions) with the largest
// blendshapes: what a decay of the blendshapes (FitOptions::blend_decay)
// holds back is read here.
void LogBlendshapeSizes(const std::vector<torch::Tensor>& texture, const torch::Tensor& blend) {
  torch::NoGradGuard no_grad;
  std::vector<torch::Tensor> flat;
  for (const torch::Tensor& t : texture) flat.push_back(t.flatten());
  const torch::Tensor per_row = blend.square().mean(1).sqrt();
  const auto top = per_row.topk(std::min<int64_t>(5, per_row.size(0)));
  std::string largest;
  for (int64_t i = 0; i < std::get<0>(top).size(0); ++i)
    largest += fmt::format("{}{} {:.3f}", i ? ", " : "", std::get<1>(top)[i].item<int64_t>(),
                           std::get<0>(top)[i].item<float>());
  spdlog::info("surface texture rms {:.3f}; its blendshapes rms {:.3f}, the largest (row rms) {}",
               torch::cat(flat).square().mean().sqrt().item<float>(), blend.square().mean().sqrt().item<float>(),
               largest);
}

}  // namespace

TrainResult TrainAvatar(Avatar& avatar, const HeadModel& model, const TrainingData& data, const FitOptions& options,
                        const std::function<void(const StepInfo&)>& progress) {
  options.Check();
  if (!data.synthetic && data.real.empty()) throw std::invalid_argument("TrainAvatar: no training data");
  const AvatarConfig& config = avatar.config();
  if (options.expression_noise > 0 && config.motion_conditioning != MotionConditioning::kFull)
    throw std::invalid_argument(
        "TrainAvatar: expression_noise needs an avatar told the expression (motion conditioning "
        "full, not " +
        std::string(MotionConditioningName(config.motion_conditioning)) + ")");
  const RealFrames real(data.real, config.output_size, options.offset_segment);
  FrameMotions motions(model);
  if (options.threads > 0) SetComputeThreads(options.threads);
  AvatarModules& modules = avatar.modules();
  if (config.surface_blend_components > 0 && modules.surface && !modules.surface->has_blend_basis())
    throw std::invalid_argument(
        "TrainAvatar: the texture's blendshapes follow principal directions of the training frames' expressions, "
        "and none are set (SetBlendDirections)");
  if (options.freeze_cnerf_layers > 0) modules.cnerf->FreezeFirstLayers(options.freeze_cnerf_layers);
  // Groups: the networks and offsets; the surface texture, whose texels each
  // see a small part of every picture (its own learning rate); its expression
  // blendshapes, when it has them (theirs).
  std::vector<torch::Tensor> params, texture, surface_params, blend_params;
  if (modules.surface) {
    texture = modules.surface->parameters();
    for (const auto& p : modules.surface->named_parameters())
      (p.key() == "blend" ? blend_params : surface_params).push_back(p.value());
  }
  for (auto& p : modules.parameters())
    if (p.requires_grad() && std::none_of(texture.begin(), texture.end(), [&](const auto& q) { return q.is_same(p); }))
      params.push_back(p);
  // The weights training started from (before a resume loads a checkpoint's:
  // the anchor is the general model's, not the interrupted run's).
  std::vector<torch::Tensor> anchors;
  if (options.anchor_weight > 0)
    for (const torch::Tensor& p : params) anchors.push_back(p.detach().clone());
  Offsets offsets;
  const bool offsets_apart = options.offset_lr_scale != 1;
  if (!real.empty() && options.learn_offsets && options.loss.offset_weight > 0)
    offsets = MakeOffsets(config, real.offset_rows(), options.freeze_identity, options.identity_offsets);
  if (offsets.enabled() && !offsets_apart) {
    params.push_back(offsets.geometry);
    params.push_back(offsets.appearance);
  }
  torch::Tensor shifts;  // (rows, 2) pixels, FitOptions::frame_shift_rate; rows as the offsets'
  if (!real.empty() && options.frame_shift_rate > 0)
    shifts = torch::zeros({real.offset_rows(), 2}, torch::requires_grad());
  // With motion blur on real frames, the camera's exposure is learnt from
  // the value given: how far the frames are smeared along their motion is
  // the camera's, and only the blur can tie a smear to the motion (the
  // networks are not told it).
  torch::Tensor exposure;
  if (!real.empty() && config.motion_blur > 0) exposure = torch::full({}, config.motion_blur, torch::requires_grad());
  std::vector<torch::optim::OptimizerParamGroup> groups = {torch::optim::OptimizerParamGroup(params)};
  std::vector<double> group_scale = {1.0};
  if (!surface_params.empty()) {
    groups.emplace_back(surface_params);
    group_scale.push_back(options.surface_lr_scale);
  }
  if (!blend_params.empty()) {
    groups.emplace_back(blend_params);
    group_scale.push_back(options.blend_lr_scale);
  }
  if (offsets.enabled() && offsets_apart) {
    groups.emplace_back(std::vector<torch::Tensor>{offsets.geometry, offsets.appearance});
    group_scale.push_back(options.offset_lr_scale);
    params.push_back(offsets.geometry);  // all-reduced with the rest
    params.push_back(offsets.appearance);
  }
  if (shifts.defined()) {
    groups.emplace_back(std::vector<torch::Tensor>{shifts});
    group_scale.push_back(options.frame_shift_rate / options.learning_rate);
    params.push_back(shifts);
  }
  if (exposure.defined()) {
    groups.emplace_back(std::vector<torch::Tensor>{exposure});
    group_scale.push_back(options.exposure_rate / options.learning_rate);
    params.push_back(exposure);
  }
  torch::optim::Adam adam(groups, torch::optim::AdamOptions(options.learning_rate));
  params.insert(params.end(), texture.begin(), texture.end());  // all of them, for the all-reduce
  std::unique_ptr<PerceptualLoss> vgg;
  TrainResult result;
  result.perceptual = "ssim";
  if (!options.loss.vgg_path.empty()) {
    vgg = std::make_unique<PerceptualLoss>(options.loss.vgg_path);
    result.perceptual = "vgg16 " + options.loss.vgg_path;
  }
  RaySampler sampler(config);
  std::unique_ptr<WeightAverage> average;
  if (options.weight_average > 0) average = std::make_unique<WeightAverage>(modules.parameters());
  const DistributedOptions& dp = options.distributed;
  const bool writes = dp.rank == 0;
  if (writes && !options.checkpoint_dir.empty()) CheckCheckpointFolder(options.checkpoint_dir, options.resume);
  if (options.resume)
    result.first_step =
        LoadCheckpoint(options.checkpoint_dir, avatar, model, adam, &offsets, shifts, exposure, average.get());
  if (!options.checkpoint_dir.empty() && writes) fs::create_directories(options.checkpoint_dir);
  std::unique_ptr<GradientAllReduce> group;
  if (dp.enabled()) group = std::make_unique<GradientAllReduce>(dp);
  const LossOptions& w = options.loss;
  std::optional<std::discrete_distribution<size_t>> draw_frame;
  if (!real.empty() && options.rare_expressions.strength > 0) {
    std::vector<Eigen::VectorXf> expressions;
    for (const RealFrames::Frame& f : real.frames()) expressions.push_back(f.data->params(f.position).expression);
    const std::vector<double> weights = RareExpressionWeights(expressions, options.rare_expressions);
    std::vector<double> sorted = weights;
    std::sort(sorted.begin(), sorted.end(), std::greater<>());
    const size_t tenth = std::max<size_t>(1, sorted.size() / 10);
    spdlog::info(
        "rare expressions: the rarest tenth of the {} training frames gets {:.0f} % of the draws (uniform: "
        "10 %), weights {:.2f}..{:.2f}",
        sorted.size(), 100 * std::accumulate(sorted.begin(), sorted.begin() + tenth, 0.0) / sorted.size(),
        sorted.back(), sorted.front());
    draw_frame.emplace(weights.begin(), weights.end());
  }
  Stopwatch watch;
  for (int step = result.first_step; step < options.iterations; ++step) {
    modules.train();
    std::uniform_real_distribution<double> u01(0, 1);
    const double p_synthetic = real.empty() ? 1.0 : !data.synthetic ? 0.0 : options.mix.SyntheticProbability(step);
    for (size_t g = 0; g < adam.param_groups().size(); ++g)
      static_cast<torch::optim::AdamOptions&>(adam.param_groups()[g].options())
          .lr(options.LearningRateAt(step) * group_scale[g]);
    adam.zero_grad();
    StepInfo info;
    info.step = step;
    for (int b = dp.rank; b < options.batch; b += dp.world_size) {
      std::mt19937 rng = SampleRng(options.seed, step, b);
      PreparedSample p;
      int real_index = -1;
      std::optional<ImageMotion> motion;
      if (u01(rng) < p_synthetic) {
        const SyntheticSample s = data.synthetic->At(static_cast<uint64_t>(step) * options.batch + b);
        p = Prepare(config, model, s.subject, s.frame, s.image_bgr, s.mask, &sampler, w.regions, w.blind_synthetic_face,
                    &rng);
        ++info.synthetic;
      } else {
        const RealFrames::Frame& f =
            real.frames()[draw_frame ? (*draw_frame)(rng)
                                     : std::uniform_int_distribution<size_t>(0, real.frames().size() - 1)(rng)];
        real_index = f.offset_row;
        const RealSample& s = f.data->At(f.position);
        const SubjectParams& subject = f.data->subject();
        FrameParams frame = s.params;
        cv::Mat image = s.image_bgr, mask = s.mask;
        bool augmented = false;
        if (u01(rng) < options.z_augmentation) {
          augmented = true;
          const double scale = std::exp(std::uniform_real_distribution<double>(std::log(options.z_scale_min),
                                                                               std::log(options.z_scale_max))(rng));
          ChangeDistance(scale, subject.intrinsics, &frame, &image, &mask);
        }
        // Drawn only when on: runs without it keep the draws (and figures) of before it existed.
        if (options.roll_augmentation > 0 && u01(rng) < options.roll_augmentation) {
          const double limit = options.roll_max_degrees * M_PI / 180;
          TurnCamera(std::uniform_real_distribution<double>(-limit, limit)(rng), subject.intrinsics, &frame, &image,
                     &mask);
          augmented = true;
        }
        // A frame moved by an augmentation no longer moves as its neighbours say: drawn sharp.
        if (config.motion_blur > 0 && !augmented) motion = motions.At(*f.data, f.position);
        p = Prepare(config, model, subject, frame, image, mask, &sampler, w.regions, false, &rng);
      }
      if (real_index >= 0 && options.expression_noise > 0) {
        std::normal_distribution<float> noise(0.0f, static_cast<float>(options.expression_noise));
        torch::Tensor psi = torch::empty({1, config.num_expression});
        for (int k = 0; k < config.num_expression; ++k) psi[0][k] = noise(rng);
        p.inputs.conditioning.geometry =
            p.inputs.conditioning.geometry + torch::constant_pad_nd(psi, {config.expression_offset(), 0});
      }
      torch::Tensor penalty = torch::zeros({});
      if (real_index >= 0 && offsets.enabled()) {
        const torch::Tensor g = offsets.geometry.narrow(0, real_index, 1) * offsets.geometry_mask;
        const torch::Tensor a = offsets.appearance.narrow(0, real_index, 1) * offsets.appearance_mask;
        p.inputs.conditioning.geometry = p.inputs.conditioning.geometry + g;
        p.inputs.conditioning.appearance = p.inputs.conditioning.appearance + a;
        penalty = w.offset_weight * (g.square().sum() + a.square().sum());
      }
      AvatarOutput out = RunAvatar(modules, p.inputs);
      if (real_index >= 0 && shifts.defined()) {
        const torch::Tensor shift = shifts.narrow(0, real_index, 1);
        out.image = ShiftImage(out.image, shift);
        if (out.coverage.defined()) out.coverage = ShiftImage(out.coverage, shift);
        penalty = penalty + w.frame_shift_weight * shift.square().sum();
      }
      // The picture as the camera saw it; the coverage stays the head's
      // outline at the instant, as the frame's mask (cut where the smeared
      // edge is half the head) has it.
      if (motion) out.image = BlurAlongMotion(out.image, *motion, exposure);
      // Blind pixels take the output itself as their target: the MSE sees no
      // error there, SSIM and VGG only through windows reaching past them.
      const torch::Tensor target = p.blind.defined() ? torch::where(p.blind, out.image.detach(), p.target) : p.target;
      const torch::Tensor mse = torch::mse_loss(out.image, target);
      const torch::Tensor weighted_mse = p.weight.defined() ? (p.weight * (out.image - target).square()).mean() : mse;
      torch::Tensor loss = w.mse_weight * weighted_mse + penalty;
      if (vgg)
        loss = loss + w.perceptual_weight * (*vgg)(out.image, target);
      else if (w.ssim_weight > 0)
        loss = loss + w.ssim_weight * (1 - Ssim(out.image, target));
      if (out.coverage.defined() && w.matte_weight > 0)
        loss = loss + w.matte_weight * torch::binary_cross_entropy(out.coverage.clamp(1e-5, 1 - 1e-5), p.mask);
      (loss / options.batch).backward();
      info.loss += loss.item<float>() / options.batch;
      info.mse += mse.item<float>() / options.batch;
    }
    if (group) {
      group->SumGradients(params);
      info.loss = static_cast<float>(group->Sum(info.loss));
      info.mse = static_cast<float>(group->Sum(info.mse));
      info.synthetic = static_cast<int>(std::lround(group->Sum(info.synthetic)));
    }
    adam.step();
    if (!anchors.empty()) {
      torch::NoGradGuard no_grad;
      const double pull = options.LearningRateAt(step) * options.anchor_weight;
      for (size_t i = 0; i < anchors.size(); ++i) params[i].sub_(pull * (params[i] - anchors[i]));
    }
    if (options.blend_decay > 0) {
      torch::NoGradGuard no_grad;
      const double shrink = options.LearningRateAt(step) * options.blend_lr_scale * options.blend_decay;
      for (torch::Tensor& p : blend_params) p.mul_(1 - shrink);
    }
    if (exposure.defined()) {
      torch::NoGradGuard no_grad;
      exposure.clamp_(0, kMaxMotionBlur);
    }
    if (average) average->Update(options.WeightAverageDecayAt(step));
    result.steps.push_back(info);
    if (writes && !options.checkpoint_dir.empty() &&
        ((step + 1) % options.checkpoint_every == 0 || step + 1 == options.iterations)) {
      modules.eval();
      SaveCheckpoint(options.checkpoint_dir, step + 1, avatar, adam, offsets, shifts, exposure, average.get());
    }
    if (progress) {
      if (average) average->Swap();  // the callback sees (and may evaluate) the average
      progress(info);
      if (average) average->Swap();
    }
  }
  if (average) average->Swap();  // the avatar keeps the average
  // Offsets and shifts over the training frames' rows (the others, held-out frames', stay zero).
  std::vector<int64_t> trained;
  for (const RealFrames::Frame& f : real.frames()) trained.push_back(f.offset_row);
  const torch::Tensor rows_trained = torch::tensor(trained);
  if (shifts.defined()) {
    torch::NoGradGuard no_grad;
    const torch::Tensor s = shifts.detach().index_select(0, rows_trained), m = s.mean(0);
    for (int k = 0; k < 2; ++k) result.frame_shift_mean[k] = m[k].item<double>();
    result.frame_shift_rms = (s - m).square().sum(1).mean().sqrt().item<double>();
  }
  if (offsets.enabled()) {
    torch::NoGradGuard no_grad;
    const auto mean_and_spread = [&](const torch::Tensor& rows, const torch::Tensor& mask, std::vector<float>* mean) {
      const torch::Tensor masked = rows.detach().index_select(0, rows_trained) * mask, m = masked.mean(0);
      mean->assign(m.data_ptr<float>(), m.data_ptr<float>() + m.numel());
      return (masked - m).square().sum().item<double>();
    };
    const double spread = mean_and_spread(offsets.geometry, offsets.geometry_mask, &result.mean_offset_geometry) +
                          mean_and_spread(offsets.appearance, offsets.appearance_mask, &result.mean_offset_appearance);
    const double told = (offsets.geometry_mask.sum() + offsets.appearance_mask.sum()).item<double>();
    result.offset_rms = std::sqrt(spread / std::max(1.0, told * static_cast<double>(trained.size())));
  }
  if (writes && !surface_params.empty() && blend_params.size() == 1)
    LogBlendshapeSizes(surface_params, blend_params[0]);
  result.seconds = watch.ElapsedSeconds();
  const int steps = options.iterations - result.first_step;
  result.samples_per_s = result.seconds > 0 ? steps * options.batch / result.seconds : 0;
  modules.eval();
  // The receiver draws with the exposure learnt. The avatar's networks are
  // new objects after this: `modules` is not used again.
  if (exposure.defined()) {
    result.exposure = exposure.item<double>();
    AvatarConfig c = avatar.config();
    c.motion_blur = result.exposure;
    avatar = avatar.WithRuntimeSwitches(c);
    avatar.modules().eval();
  }
  return result;
}

double SetBlendDirections(Avatar& avatar, const PreparedDataset& data) {
  const AvatarConfig& c = avatar.config();
  if (c.surface_blend_components == 0 || !avatar.modules().surface) return 0;
  std::vector<Eigen::VectorXf> expressions;
  for (int i : data.train()) expressions.push_back(Resized(data.params(i).expression, c.num_expression));
  const ExpressionDirections d = PrincipalExpressions(expressions, c.surface_blend_components);
  const auto tensor = [](const Eigen::MatrixXf& m) {
    const Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> rows = m;
    return torch::from_blob(const_cast<float*>(rows.data()), {rows.rows(), rows.cols()}).clone();
  };
  avatar.modules().surface->SetBlendBasis(tensor(d.mean).view({-1}), tensor(d.directions), tensor(d.low).view({-1}),
                                          tensor(d.high).view({-1}));
  return d.explained;
}

TrainResult FitOnSynthetic(Avatar& avatar, const HeadModel& model, SyntheticData& data, const FitOptions& options,
                           const std::function<void(const StepInfo&)>& progress) {
  return TrainAvatar(avatar, model, TrainingData{&data, {}}, options, progress);
}

namespace {

// Frames of an avatar as the receiver shows them (RenderAvatarFrame: the same
// preparation, networks and 8-bit picture), its buffers reused frame to frame.
class ShownFrames {
 public:
  explicit ShownFrames(Avatar& avatar) : avatar_(avatar), sampler_(avatar.config()) {}
  cv::Mat Render(const HeadModel& model, const HeadIdentity& identity, const SubjectParams& subject,
                 const FrameParams& frame) {
    cv::Mat bgr;
    RenderAvatarFrame(avatar_.modules(), avatar_.config(), model, identity, subject, frame, &sampler_, &buffers_, &bgr);
    return bgr;
  }

 private:
  Avatar& avatar_;
  RaySampler sampler_;
  AvatarFrameInputs buffers_;
};

// Adds the figures of the shown picture against its target to `r`.
void Score(const cv::Mat& shown_bgr, const cv::Mat& target_bgr, EvalResult* r) {
  const ImageScore s = ScoreImage(BgrToImageTensor(shown_bgr), BgrToImageTensor(target_bgr));
  r->psnr.push_back(s.psnr);
  r->ssim.push_back(s.ssim);
  r->mse_mean += s.mse;
}

void Finish(const SampleStats& ms, EvalResult* r) {
  r->count = static_cast<int>(r->psnr.size());
  if (r->count == 0) return;
  for (int i = 0; i < r->count; ++i) {
    r->psnr_mean += r->psnr[i] / r->count;
    r->ssim_mean += r->ssim[i] / r->count;
  }
  r->mse_mean /= r->count;
  r->ms_median = ms.Median();
}

}  // namespace

EvalResult EvaluateOnSynthetic(Avatar& avatar, const HeadModel& model, const SyntheticData& data, int count,
                               uint64_t first) {
  avatar.modules().eval();
  torch::InferenceMode inference;
  SampleStats ms;
  EvalResult r;
  ShownFrames shown(avatar);
  for (int i = 0; i < count; ++i) {
    const SyntheticSample s = data.At(first + i);
    Stopwatch watch;
    const cv::Mat bgr = shown.Render(model, model.MakeIdentity(s.subject.shape.cast<double>()), s.subject, s.frame);
    ms.Add(watch.ElapsedMs());
    Score(bgr, s.image_bgr, &r);
  }
  Finish(ms, &r);
  return r;
}

EvalResult EvaluateOnFrames(Avatar& avatar, const HeadModel& model, const SubjectParams& subject,
                            const std::vector<FrameParams>& frames, const std::function<cv::Mat(int)>& target,
                            const std::function<void(int, const cv::Mat&, const cv::Mat&)>& each) {
  avatar.modules().eval();
  torch::InferenceMode inference;
  SampleStats ms;
  EvalResult r;
  ShownFrames shown(avatar);
  const HeadIdentity identity = model.MakeIdentity(subject.shape.cast<double>());
  for (int k = 0; k < static_cast<int>(frames.size()); ++k) {
    const cv::Mat truth = target(k);
    if (truth.empty()) continue;
    Stopwatch watch;
    const cv::Mat bgr = shown.Render(model, identity, subject, frames[k]);
    ms.Add(watch.ElapsedMs());
    Score(bgr, truth, &r);
    if (each) each(k, truth, bgr);
  }
  Finish(ms, &r);
  return r;
}

EvalResult EvaluateOnDataset(Avatar& avatar, const HeadModel& model, const PreparedDataset& data,
                             const std::vector<int>& positions,
                             const std::function<void(int, const cv::Mat&, const cv::Mat&)>& render, bool skin_colour,
                             const OutlineOptions* outline, int outline_every) {
  if (outline_every < 1) throw std::invalid_argument("EvaluateOnDataset: outline_every must be at least 1");
  std::vector<FrameParams> frames;
  std::vector<float> measured;
  for (size_t k = 0; k < positions.size(); ++k) {
    const int i = positions[k];
    frames.push_back(data.At(i).params);
    if (!skin_colour) frames.back().skin_colour.reset();
    if (!outline) continue;
    if (k % outline_every == 0)
      measured =
          MeasureOutline(data.At(i).mask,
                         OutlineFrame::Of(data.subject().intrinsics, frames.back().CamFromHead(), *outline), *outline);
    frames.back().outline = measured;
  }
  return EvaluateOnFrames(
      avatar, model, data.subject(), frames,
      [&](int k) {
        const RealSample& s = data.At(positions[k]);
        return MaskedTarget(s.image_bgr, s.mask);
      },
      [&](int k, const cv::Mat& target, const cv::Mat& bgr) {
        if (render) render(positions[k], target, bgr);
      });
}

ConditioningMasks OffsetMasks(const AvatarConfig& config, bool freeze_identity) {
  ConditioningMasks m;
  m.geometry = torch::ones({1, config.conditioning_dim()});
  m.appearance = torch::ones({1, config.appearance_dim()});
  if (freeze_identity) {
    m.geometry.narrow(1, 0, config.num_shape).zero_();                                                 // beta first
    m.appearance.narrow(1, config.appearance_dim() - config.num_texture, config.num_texture).zero_();  // tau last
  }
  // What the networks are not told of a frame's motion, a per-frame code
  // must not tell them either: the training frames would be memorised there.
  for (int i = config.num_shape; i < config.conditioning_dim(); ++i)
    if (!config.Conditions(i)) m.geometry[0][i] = 0;
  return m;
}

Eigen::VectorXf Resized(const Eigen::VectorXf& v, int n) {
  Eigen::VectorXf out = Eigen::VectorXf::Zero(n);
  const int k = std::min<int>(n, static_cast<int>(v.size()));
  out.head(k) = v.head(k);
  return out;
}

cv::Mat RenderAvatarBgr(Avatar& avatar, const HeadModel& model, const SubjectParams& subject,
                        const FrameParams& frame) {
  avatar.modules().eval();
  torch::InferenceMode inference;
  return ShownFrames(avatar).Render(model, model.MakeIdentity(subject.shape.cast<double>()), subject, frame);
}

}  // namespace headcast
