// Benchmark suite "codec": bits per frame and the error the codec adds, on a
// synthetic talking-head sequence of the built-in head or on a recording of
// any head model; with an avatar, the PSNR the quantisation costs (against the
// built-in head's own renders, or a prepared dataset's held-out frames).
#include <algorithm>
#include <opencv2/core.hpp>
#include <stdexcept>

#include "bench/bench.h"
#include "common/avatar/avatar_renderer.h"
#include "common/codec/param_codec.h"
#include "common/headmodel/builtin_head.h"
#include "common/headmodel/head_model_io.h"
#include "common/headmodel/head_render.h"
#include "common/headmodel/synthetic_motion.h"
#include "proto/recording.h"
#include "training/avatar_fit.h"
#include "training/dataset.h"

namespace headcast::bench {
namespace {

// Values of `b` further from `a` than half their quantisation step (the
// codec's bound; rounding error of the float values aside).
int BeyondHalfStep(const CodecLayout& layout, const FrameParams& a, const FrameParams& b) {
  int beyond = 0;
  auto check = [&](double x, double y, float step) { beyond += std::abs(x - y) > 0.5 * step * (1 + 1e-5) + 1e-7; };
  size_t k = 0;
  for (int c : layout.expression_components)
    check(c < a.expression.size() ? a.expression[c] : 0.f, b.expression[c], layout.steps[k++]);
  const Eigen::Vector3f* va[] = {&a.jaw, &a.neck, &a.left_eye, &a.right_eye, &a.cam_rotation, &a.cam_translation};
  const Eigen::Vector3f* vb[] = {&b.jaw, &b.neck, &b.left_eye, &b.right_eye, &b.cam_rotation, &b.cam_translation};
  for (int g = 0; g < 6; ++g)
    for (int i = 0; i < 3; ++i) check((*va[g])[i], (*vb[g])[i], layout.steps[k++]);
  return beyond;
}

// Encodes and decodes `frames` in order; the decoded frames, in order.
std::vector<FrameParams> RoundTrip(const CodecLayout& layout, const std::vector<FrameParams>& frames) {
  ParamEncoder enc(layout);
  ParamDecoder dec(layout);
  std::vector<FrameParams> out(frames.size());
  for (size_t i = 0; i < frames.size(); ++i) {
    std::string why;
    if (!dec.Decode(enc.Encode(frames[i]), &out[i], &why)) throw std::runtime_error("decode failed: " + why);
  }
  return out;
}

// The dataset's frames at `positions` in the order they were captured (a
// continuous stretch for a held-out split).
std::vector<int> InCaptureOrder(const PreparedDataset& data, std::vector<int> positions) {
  std::sort(positions.begin(), positions.end(), [&](int a, int b) { return data.At(a).frame < data.At(b).frame; });
  return positions;
}

// The PSNR the codec costs on the held-out frames of a prepared dataset: the
// avatar against the true (masked) frames from the tracked and from the
// decoded parameters, and the two renders against each other.
nlohmann::json CostOnDataset(const BenchOptions& options, const HeadModel& model, const CodecLayout& layout) {
  const PreparedDataset data = PreparedDataset::Load(options.dataset, model, options.resolution, false);
  Avatar avatar = Avatar::Load(options.avatar, model);
  const std::vector<int> test = InCaptureOrder(data, data.test());
  if (test.empty()) throw std::runtime_error(options.dataset + " has no held-out frames");
  std::vector<FrameParams> tracked;
  for (int i : test) tracked.push_back(data.At(i).params);
  const std::vector<FrameParams> decoded = RoundTrip(layout, tracked);
  SampleStats original, coded, cost, between;
  size_t k = 0;
  std::vector<std::pair<double, int>> worst;  // (cost, source frame)
  EvaluateOnDataset(avatar, model, data, test, [&](int position, const cv::Mat& truth, const cv::Mat& bgr) {
    const cv::Mat from_decoded = RenderAvatarBgr(avatar, model, data.subject(), decoded[k++]);
    const double a = cv::PSNR(bgr, truth), b = cv::PSNR(from_decoded, truth);
    original.Add(a);
    coded.Add(b);
    cost.Add(a - b);
    worst.emplace_back(a - b, data.At(position).frame);
    between.Add(cv::PSNR(bgr, from_decoded));
  });
  std::sort(worst.rbegin(), worst.rend());
  worst.resize(std::min<size_t>(worst.size(), 3));
  nlohmann::json worst_frames = nlohmann::json::array();
  for (auto [c, frame] : worst) worst_frames.push_back({{"frame", frame}, {"cost_db", c}});
  return {{"dataset_test_frames", test.size()},
          {"costliest_frames", worst_frames},
          {"avatar_psnr_db_original_params", original.Mean()},
          {"avatar_psnr_db_decoded_params", coded.Mean()},
          {"codec_psnr_cost_db_mean", cost.Mean()},
          {"codec_psnr_cost_db_max", cost.Max()},
          {"decoded_vs_original_render_psnr_db_mean", between.Mean()},
          {"decoded_vs_original_render_psnr_db_min", between.Min()}};
}

// The same against the built-in head's own renders of the synthetic sequence.
nlohmann::json CostOnSynthetic(const BenchOptions& options, const HeadModel& model, const CodecLayout& layout,
                               const std::vector<FrameParams>& frames) {
  auto shared = std::make_shared<const HeadModel>(model);
  AvatarRenderer renderer(shared, Avatar::Load(options.avatar, model));
  const SubjectParams& subject = renderer.avatar().subject();
  const std::vector<FrameParams> decoded = RoundTrip(layout, frames);
  SampleStats original, coded, cost;
  for (size_t i = 0; i < std::min<size_t>(frames.size(), 300); i += 5) {
    const FrameParams& f = frames[i];
    HeadModelParams hp;
    hp.shape = subject.shape.cast<double>();
    hp.expression = f.expression.cast<double>();
    hp.pose = f.HeadPose();
    HeadRenderOptions ro;
    std::copy(subject.light.begin(), subject.light.end(), ro.light.begin());
    const cv::Mat truth = RenderHead(model, model.Forward(hp).vertices, f.CamFromHead(), subject.intrinsics,
                                     AlbedoTexture(model, subject.texture.cast<double>()), ro)
                              .image_bgr;
    cv::Mat a, b;
    renderer.Render(f, &a);
    renderer.Render(decoded[i], &b);
    original.Add(cv::PSNR(a, truth));
    coded.Add(cv::PSNR(b, truth));
    cost.Add(cv::PSNR(a, truth) - cv::PSNR(b, truth));
  }
  return {{"avatar_psnr_db_original_params", original.Mean()},
          {"avatar_psnr_db_decoded_params", coded.Mean()},
          {"codec_psnr_cost_db_mean", cost.Mean()},
          {"codec_psnr_cost_db_max", cost.Max()}};
}

}  // namespace

nlohmann::json RunCodecSuite(const BenchOptions& options) {
  if (!options.dataset.empty() && options.avatar.empty())
    throw std::invalid_argument("codec: --data needs --avatar (the PSNR cost is measured through an avatar)");
  const HeadModel model = LoadHeadModelSpec(options.head_model);
  std::vector<FrameParams> frames;
  std::string what;
  if (!options.recording.empty()) {
    RecordingInfo info;
    frames = ReadRecording(options.recording, &info);
    if (info.head_model_fingerprint != model.fingerprint())
      throw std::invalid_argument(options.recording + " was recorded with head model '" + info.head_model_name +
                                  "', not with " + options.head_model + " (give it with --head-model)");
    what = "a recording (" + info.head_model_name + ", " + std::to_string(frames.size()) + " frames)";
  } else {
    if (options.head_model != "builtin")
      throw std::invalid_argument("codec: the synthetic sequence is the built-in head's; give --recording for " +
                                  options.head_model);
    for (int i = 0; i < std::max(30, options.repeats * 10); ++i) frames.push_back(SyntheticTalkingHead(model, i));
    what = "a synthetic talking-head sequence of the built-in head, 30 fps";
  }
  const CodecLayout layout = CodecLayout::FromModel(model, options.codec_error_m, {}, options.key_interval);
  ParamEncoder enc(layout);
  ParamDecoder dec(layout);
  SampleStats bits, key_bits, delta_bits, vertex_error_mm, encode_us, decode_us;
  double max_abs_err[4] = {0, 0, 0, 0};  // expression, joint rotation (rad), cam rotation (rad), translation (m)
  int beyond_half_step = 0;
  for (size_t i = 0; i < frames.size(); ++i) {
    const FrameParams& f = frames[i];
    Stopwatch w;
    const std::string packet = enc.Encode(f);
    encode_us.Add(w.ElapsedUs());
    FrameParams out;
    std::string why;
    w.Restart();
    if (!dec.Decode(packet, &out, &why)) throw std::runtime_error("decode failed: " + why);
    decode_us.Add(w.ElapsedUs());
    bits.Add(8.0 * packet.size());
    beyond_half_step += BeyondHalfStep(layout, f, out);
    (static_cast<uint8_t>(packet[0]) & 0x20 ? key_bits : delta_bits).Add(8.0 * packet.size());
    max_abs_err[0] = std::max<double>(max_abs_err[0], (f.expression - out.expression).cwiseAbs().maxCoeff());
    for (auto [a, b] : {std::pair{&f.jaw, &out.jaw}, {&f.neck, &out.neck}, {&f.left_eye, &out.left_eye}})
      max_abs_err[1] = std::max<double>(max_abs_err[1], (*a - *b).cwiseAbs().maxCoeff());
    max_abs_err[2] = std::max<double>(max_abs_err[2], (f.cam_rotation - out.cam_rotation).cwiseAbs().maxCoeff());
    max_abs_err[3] = std::max<double>(max_abs_err[3], (f.cam_translation - out.cam_translation).cwiseAbs().maxCoeff());
    if (i % 10 == 0) {
      // What a viewer sees: the posed mesh (head frame) from original vs decoded parameters.
      HeadModelParams pa, pb;
      pa.expression = f.expression.cast<double>();
      pa.pose = f.HeadPose();
      pb.expression = out.expression.cast<double>();
      pb.pose = out.HeadPose();
      vertex_error_mm.Add(1e3 * (model.Forward(pa).vertices - model.Forward(pb).vertices).rowwise().norm().maxCoeff());
    }
  }
  nlohmann::json out;
  out["suite"] = "codec";
  out["what"] = "ParamCodec v" + std::to_string(kCodecVersion) + " on " + what;
  out["head_model"] = model.data().name;
  out["frames"] = frames.size();
  out["values_per_frame"] = layout.num_values();
  out["key_frame_interval"] = layout.key_frame_interval;
  out["max_vertex_error_per_step_mm"] = options.codec_error_m * 1e3;
  out["bits_per_frame_mean"] = bits.Mean();
  out["bits_per_frame_key_mean"] = key_bits.Mean();
  out["bits_per_frame_delta_mean"] = delta_bits.Mean();
  out["payload_kbps_at_30fps"] = bits.Mean() * 30 / 1000;
  {
    // The skin colour's share: the same frames coded by a layout without it.
    ParamEncoder without(CodecLayout::FromModel(model, options.codec_error_m, {}, options.key_interval, false));
    double bits_without = 0;
    for (const FrameParams& f : frames) bits_without += 8.0 * without.Encode(f).size();
    bits_without /= static_cast<double>(frames.size());
    out["bits_per_frame_mean_without_skin_colour"] = bits_without;
    out["frames_with_skin_colour"] =
        std::count_if(frames.begin(), frames.end(), [](const FrameParams& f) { return f.skin_colour.has_value(); });
  }
  {
    // The outline's share: a layout without it.
    ParamEncoder without(
        CodecLayout::FromModel(model, options.codec_error_m, {}, options.key_interval, true, /*outline_bins=*/0));
    double bits_without = 0;
    for (const FrameParams& f : frames) bits_without += 8.0 * without.Encode(f).size();
    out["bits_per_frame_mean_without_outline"] = bits_without / static_cast<double>(frames.size());
    out["frames_with_outline"] =
        std::count_if(frames.begin(), frames.end(), [](const FrameParams& f) { return !f.outline.empty(); });
  }
  out["max_abs_error"] = {{"expression", max_abs_err[0]},
                          {"joint_rotation_rad", max_abs_err[1]},
                          {"cam_rotation_rad", max_abs_err[2]},
                          {"cam_translation_m", max_abs_err[3]}};
  out["values_beyond_half_a_step"] = beyond_half_step;
  out["max_vertex_error_mm_median"] = vertex_error_mm.Median();
  out["max_vertex_error_mm_max"] = vertex_error_mm.Max();
  if (!options.avatar.empty()) {
    out["avatar"] = options.avatar;
    out.update(options.dataset.empty() ? CostOnSynthetic(options, model, layout, frames)
                                       : CostOnDataset(options, model, layout));
  }
  out["encode_us_median"] = encode_us.Median();
  out["decode_us_median"] = decode_us.Median();
  return out;
}

}  // namespace headcast::bench
