// Benchmark suite "codec": bits per frame and the error the codec adds, on a
// synthetic talking-head sequence of the built-in head (or a recording).
#include <cmath>

#include "bench/bench.h"
#include "common/avatar/avatar_renderer.h"
#include "common/codec/param_codec.h"
#include "common/headmodel/builtin_head.h"
#include "common/headmodel/head_render.h"
#include "common/headmodel/synthetic_motion.h"

namespace headcast::bench {

nlohmann::json RunCodecSuite(const BenchOptions& options) {
  const HeadModel model = MakeBuiltinHead();
  const CodecLayout layout = CodecLayout::FromModel(model, 2e-4);
  ParamEncoder enc(layout);
  ParamDecoder dec(layout);
  const int frames = std::max(30, options.repeats * 10);
  SampleStats bits, key_bits, delta_bits, vertex_error_mm, encode_us, decode_us;
  double max_abs_err[4] = {0, 0, 0, 0};  // expression, joint rotation (rad), cam rotation (rad), translation (m)
  for (int i = 0; i < frames; ++i) {
    const FrameParams f = SyntheticTalkingHead(model, i);
    Stopwatch w;
    const std::string packet = enc.Encode(f);
    encode_us.Add(w.ElapsedUs());
    FrameParams out;
    std::string why;
    w.Restart();
    if (!dec.Decode(packet, &out, &why)) throw std::runtime_error("decode failed: " + why);
    decode_us.Add(w.ElapsedUs());
    bits.Add(8.0 * packet.size());
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
  out["what"] =
      "ParamCodec on a synthetic talking-head sequence of the built-in head, 30 fps, all 13 expression components";
  out["frames"] = frames;
  out["values_per_frame"] = layout.num_values();
  out["key_frame_interval"] = layout.key_frame_interval;
  out["bits_per_frame_mean"] = bits.Mean();
  out["bits_per_frame_key_mean"] = key_bits.Mean();
  out["bits_per_frame_delta_mean"] = delta_bits.Mean();
  out["payload_kbps_at_30fps"] = bits.Mean() * 30 / 1000;
  out["max_abs_error"] = {{"expression", max_abs_err[0]},
                          {"joint_rotation_rad", max_abs_err[1]},
                          {"cam_rotation_rad", max_abs_err[2]},
                          {"cam_translation_m", max_abs_err[3]}};
  out["max_vertex_error_mm_median"] = vertex_error_mm.Median();
  out["max_vertex_error_mm_max"] = vertex_error_mm.Max();
  if (!options.avatar.empty()) {
    // The PSNR the codec costs in rendered images: the avatar against the head
    // model's own render (ground truth), from original and from decoded parameters.
    auto shared = std::make_shared<const HeadModel>(model);
    AvatarRenderer renderer(shared, Avatar::Load(options.avatar, model));
    const SubjectParams& subject = renderer.avatar().subject();
    ParamEncoder e2(layout);
    ParamDecoder d2(layout);
    SampleStats psnr_original, psnr_decoded, cost;
    auto psnr = [](const cv::Mat& a, const cv::Mat& b) { return cv::PSNR(a, b); };
    for (int i = 0; i < std::min(frames, 300); ++i) {
      FrameParams f = SyntheticTalkingHead(model, i);
      FrameParams decoded;
      std::string why;
      if (!d2.Decode(e2.Encode(f), &decoded, &why)) throw std::runtime_error(why);
      if (i % 5) continue;
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
      renderer.Render(decoded, &b);
      psnr_original.Add(psnr(a, truth));
      psnr_decoded.Add(psnr(b, truth));
      cost.Add(psnr(a, truth) - psnr(b, truth));
    }
    out["avatar"] = options.avatar;
    out["avatar_psnr_db_original_params"] = psnr_original.Mean();
    out["avatar_psnr_db_decoded_params"] = psnr_decoded.Mean();
    out["codec_psnr_cost_db_mean"] = cost.Mean();
    out["codec_psnr_cost_db_max"] = cost.Max();
  }
  out["encode_us_median"] = encode_us.Median();
  out["decode_us_median"] = decode_us.Median();
  return out;
}

}  // namespace headcast::bench
