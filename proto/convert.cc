// Conversions between headcast types and proto messages.
#include "proto/convert.h"

#include "common/headmodel/head_outline.h"

namespace headcast {
namespace {

template <typename Field>
void PutVector3(const Eigen::Vector3f& v, Field* f) {
  f->Clear();
  for (int i = 0; i < 3; ++i) f->Add(v[i]);
}

template <typename Field>
bool GetVector3(const Field& f, const char* name, Eigen::Vector3f* v, std::string* why) {
  if (f.size() == 0) {
    v->setZero();  // absent = zero rotation, as proto3 leaves empty fields out
    return true;
  }
  if (f.size() != 3) {
    if (why) *why = std::string(name) + " needs 3 values, got " + std::to_string(f.size());
    return false;
  }
  *v = Eigen::Vector3f(f[0], f[1], f[2]);
  return true;
}

}  // namespace

void ToProto(const FrameParams& in, v1::FrameParams* out) {
  out->Clear();
  for (int i = 0; i < in.expression.size(); ++i) out->add_expression(in.expression[i]);
  PutVector3(in.jaw, out->mutable_jaw());
  PutVector3(in.neck, out->mutable_neck());
  PutVector3(in.left_eye, out->mutable_left_eye());
  PutVector3(in.right_eye, out->mutable_right_eye());
  PutVector3(in.cam_rotation, out->mutable_cam_rotation());
  PutVector3(in.cam_translation, out->mutable_cam_translation());
  out->set_capture_time_s(in.capture_time_s);
  out->set_sequence(in.sequence);
  out->set_confidence(in.confidence);
  if (in.skin_colour) PutVector3(*in.skin_colour, out->mutable_skin_colour());
  out->mutable_outline()->Assign(in.outline.begin(), in.outline.end());
}

bool FromProto(const v1::FrameParams& in, FrameParams* out, std::string* why) {
  out->expression = Eigen::Map<const Eigen::VectorXf>(in.expression().data(), in.expression_size());
  if (!GetVector3(in.jaw(), "jaw", &out->jaw, why) || !GetVector3(in.neck(), "neck", &out->neck, why) ||
      !GetVector3(in.left_eye(), "left_eye", &out->left_eye, why) ||
      !GetVector3(in.right_eye(), "right_eye", &out->right_eye, why) ||
      !GetVector3(in.cam_rotation(), "cam_rotation", &out->cam_rotation, why) ||
      !GetVector3(in.cam_translation(), "cam_translation", &out->cam_translation, why))
    return false;
  out->capture_time_s = in.capture_time_s();
  out->sequence = in.sequence();
  out->confidence = in.confidence();
  out->skin_colour.reset();
  if (in.skin_colour_size() > 0) {  // absent: not measured
    Eigen::Vector3f rgb;
    if (!GetVector3(in.skin_colour(), "skin_colour", &rgb, why)) return false;
    out->skin_colour = rgb;
  }
  out->outline.assign(in.outline().begin(), in.outline().end());
  return OutlineIsValid(out->outline, why);
}

void ToProto(const SubjectParams& in, v1::SubjectParams* out) {
  out->Clear();
  for (int i = 0; i < in.shape.size(); ++i) out->add_shape(in.shape[i]);
  for (int i = 0; i < in.texture.size(); ++i) out->add_texture(in.texture[i]);
  for (float v : in.light) out->add_light(v);
  auto* k = out->mutable_intrinsics();
  k->set_fx(in.intrinsics.fx);
  k->set_fy(in.intrinsics.fy);
  k->set_cx(in.intrinsics.cx);
  k->set_cy(in.intrinsics.cy);
  k->set_width(in.intrinsics.width);
  k->set_height(in.intrinsics.height);
}

bool FromProto(const v1::SubjectParams& in, SubjectParams* out, std::string* why) {
  out->shape = Eigen::Map<const Eigen::VectorXf>(in.shape().data(), in.shape_size());
  out->texture = Eigen::Map<const Eigen::VectorXf>(in.texture().data(), in.texture_size());
  if (in.light_size() != 0 && in.light_size() != 27) {
    if (why) *why = "light needs 27 values, got " + std::to_string(in.light_size());
    return false;
  }
  out->light.fill(0.f);
  for (int i = 0; i < in.light_size(); ++i) out->light[i] = in.light(i);
  const auto& k = in.intrinsics();
  out->intrinsics.fx = k.fx();
  out->intrinsics.fy = k.fy();
  out->intrinsics.cx = k.cx();
  out->intrinsics.cy = k.cy();
  out->intrinsics.width = static_cast<int>(k.width());
  out->intrinsics.height = static_cast<int>(k.height());
  return true;
}

void ToProto(const CodecLayout& in, double fps, v1::ParameterLayout* out) {
  out->Clear();
  out->set_num_expression(in.num_expression);
  for (int c : in.expression_components) out->add_expression_components(c);
  for (float s : in.steps) out->add_steps(s);
  out->set_key_frame_interval(in.key_frame_interval);
  out->set_fps(fps);
  out->set_codec_version(kCodecVersion);
  out->set_head_model_fingerprint(in.head_model_fingerprint);
  out->set_skin_colour(in.skin_colour);
  out->set_outline_bins(static_cast<uint32_t>(in.outline_bins));
}

bool FromProto(const v1::ParameterLayout& in, CodecLayout* out, std::string* why) {
  if (in.codec_version() != kCodecVersion) {
    if (why)
      *why = "codec version " + std::to_string(in.codec_version()) + ", this build speaks " +
             std::to_string(kCodecVersion);
    return false;
  }
  // Values too large for an int are refused as received, not clamped (a
  // clamped figure in the error would name something the peer never sent).
  constexpr uint32_t kLargest = 1u << 20;
  auto too_large = [&](const char* name, uint32_t value) {
    if (value <= kLargest) return false;
    if (why) *why = std::string(name) + " " + std::to_string(value) + " is out of range";
    return true;
  };
  if (too_large("num_expression", in.num_expression()) || too_large("key_frame_interval", in.key_frame_interval()))
    return false;
  for (uint32_t c : in.expression_components())
    if (too_large("expression component", c)) return false;
  CodecLayout l;
  l.num_expression = static_cast<int>(in.num_expression());
  l.expression_components.assign(in.expression_components().begin(), in.expression_components().end());
  l.steps.assign(in.steps().begin(), in.steps().end());
  l.key_frame_interval = static_cast<int>(in.key_frame_interval());
  l.head_model_fingerprint = in.head_model_fingerprint();  // Check bounds its length
  l.skin_colour = in.skin_colour();
  if (in.outline_bins() > static_cast<uint32_t>(kMaxOutlineBins)) {
    if (why)
      *why = "outline_bins " + std::to_string(in.outline_bins()) + " is more than " + std::to_string(kMaxOutlineBins);
    return false;
  }
  l.outline_bins = static_cast<int>(in.outline_bins());
  try {
    l.Check();
  } catch (const std::invalid_argument& e) {
    if (why) *why = e.what();
    return false;
  }
  *out = l;
  return true;
}

}  // namespace headcast
