// The parameter codec.
#include "common/codec/param_codec.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "common/codec/bit_stream.h"
#include "common/core/options.h"

namespace headcast {
namespace {

constexpr int kKeyOrder = 6;  // Exp-Golomb order for absolute values in key frames
constexpr int kMaxOrder = 20;
constexpr int kMagnitudeShift = 3;  // running mean of |residual| in 1/8 units

// Adaptive Exp-Golomb order from the running mean magnitude (same on both ends).
int OrderFor(int magnitude) {
  const int mean = magnitude >> kMagnitudeShift;
  int k = 0;
  while (k < kMaxOrder && (1 << (k + 1)) <= mean + 1) ++k;
  return k;
}
void UpdateMagnitude(int64_t residual, int* magnitude) {
  const int64_t a = std::min<int64_t>(std::llabs(residual), 1 << 20);
  *magnitude += static_cast<int>(a - (*magnitude >> kMagnitudeShift));  // mean over ~8 frames, scaled by 8
}

// The coded values of a frame, in layout order.
std::vector<double> Values(const CodecLayout& layout, const FrameParams& f) {
  std::vector<double> v;
  v.reserve(layout.num_values());
  for (int c : layout.expression_components) v.push_back(c < f.expression.size() ? f.expression[c] : 0.0);
  for (const Eigen::Vector3f* r : {&f.jaw, &f.neck, &f.left_eye, &f.right_eye, &f.cam_rotation, &f.cam_translation})
    for (int i = 0; i < 3; ++i) v.push_back((*r)[i]);
  return v;
}

void SetValues(const CodecLayout& layout, const std::vector<double>& v, FrameParams* f) {
  f->expression = Eigen::VectorXf::Zero(layout.num_expression);
  size_t k = 0;
  for (int c : layout.expression_components) f->expression[c] = static_cast<float>(v[k++]);
  for (Eigen::Vector3f* r : {&f->jaw, &f->neck, &f->left_eye, &f->right_eye, &f->cam_rotation, &f->cam_translation})
    for (int i = 0; i < 3; ++i) (*r)[i] = static_cast<float>(v[k++]);
}

// Largest magnitude a value may decode to (garbage and hostile packets are refused).
double Limit(const CodecLayout& layout, int index) {
  const int e = static_cast<int>(layout.expression_components.size());
  if (index < e) return 10.0;       // expression coefficients
  if (index < e + 15) return M_PI;  // rotations, radians
  return 20.0;                      // translation, metres
}

}  // namespace

void CodecLayout::Check() const {
  OptionsCheck c("CodecLayout");
  c.InRange("num_expression", num_expression, 0, 4096).InRange("key_frame_interval", key_frame_interval, 1, 100000);
  for (size_t i = 0; i < expression_components.size(); ++i) {
    c.That(expression_components[i] >= 0 && expression_components[i] < num_expression,
           "expression component " + std::to_string(expression_components[i]) + " outside [0, num_expression)");
    c.That(i == 0 || expression_components[i] > expression_components[i - 1], "expression components must ascend");
  }
  c.That(static_cast<int>(steps.size()) == num_values(),
         "steps has " + std::to_string(steps.size()) + " values, the layout codes " + std::to_string(num_values()));
  for (float s : steps) c.That(s > 1e-7f && s < 10.f && std::isfinite(s), "every step must be in (1e-7, 10)");
  c.That(head_model_fingerprint.size() <= kMaxFingerprintBytes, "the head-model fingerprint is too long");
  c.ThrowIfErrors();
}

CodecLayout CodecLayout::FromModel(const HeadModel& model, double err, std::vector<int> components, int key_interval) {
  CodecLayout l;
  l.num_expression = model.num_expression();
  l.key_frame_interval = key_interval;
  l.head_model_fingerprint = model.fingerprint();
  if (components.empty())
    for (int i = 0; i < model.num_expression(); ++i) components.push_back(i);
  std::sort(components.begin(), components.end());
  l.expression_components = components;
  // The indices are checked before they index the basis (a user typed them).
  for (size_t i = 0; i < components.size(); ++i) {
    if (components[i] < 0 || components[i] >= model.num_expression())
      throw std::invalid_argument("expression component " + std::to_string(components[i]) + " is outside 0.." +
                                  std::to_string(model.num_expression() - 1) + " (the head model has " +
                                  std::to_string(model.num_expression()) + " expression components)");
    if (i > 0 && components[i] == components[i - 1])
      throw std::invalid_argument("expression component " + std::to_string(components[i]) + " is listed twice");
  }
  const auto& d = model.data();
  const int n = model.num_vertices();
  for (int c : components) {
    // Sensitivity: the largest vertex displacement per unit coefficient.
    double sensitivity = 0;
    for (int i = 0; i < n; ++i)
      sensitivity = std::max<double>(sensitivity, d.expressiondirs.block(3 * i, c, 3, 1).norm());
    l.steps.push_back(static_cast<float>(std::clamp(err / std::max(sensitivity, 1e-9), 1e-4, 1.0)));
  }
  // Rotations move points by angle x radius: the mesh's extent about each joint.
  const HeadModelOutput rest = model.Forward(HeadModelParams{});
  auto radius_about = [&](int joint, int weight_joint) {
    double r = 0;
    for (int i = 0; i < n; ++i)
      if (weight_joint < 0 || d.weights(i, weight_joint) > 0.5f)
        r = std::max<double>(r, (rest.vertices.row(i) - rest.joints.row(joint)).norm());
    return std::max(r, 0.01);
  };
  const double head_radius = radius_about(kRootJoint, -1);
  const double jaw_radius = model.JointIsArticulated(kJawJoint) ? radius_about(kJawJoint, kJawJoint) : head_radius;
  const double eye_radius =
      model.JointIsArticulated(kLeftEyeJoint) ? radius_about(kLeftEyeJoint, kLeftEyeJoint) : 0.012;
  for (double r : {jaw_radius, head_radius, eye_radius, eye_radius, head_radius})
    for (int i = 0; i < 3; ++i) l.steps.push_back(static_cast<float>(err / r));
  for (int i = 0; i < 3; ++i) l.steps.push_back(static_cast<float>(err));
  l.Check();
  return l;
}

ParamEncoder::ParamEncoder(CodecLayout layout) : layout_(std::move(layout)) {
  layout_.Check();
  previous_.assign(layout_.num_values(), 0);
  magnitude_.assign(layout_.num_values(), 0);
}

std::string ParamEncoder::Encode(const FrameParams& f, double origin) {
  const bool key = force_key_ || since_key_ >= layout_.key_frame_interval - 1;
  const std::vector<double> values = Values(layout_, f);
  const int64_t time_ms = static_cast<int64_t>(std::llround((f.capture_time_s - origin) * 1000));
  std::string packet;
  packet.push_back(static_cast<char>((kCodecVersion << 6) | (key ? 0x20 : 0)));
  PutVarint(key ? 0 : coded_ + 1, &packet);  // 0 marks a key frame's fresh chain
  if (key) {
    PutVarint(f.sequence, &packet);
    PutVarint(static_cast<uint64_t>(std::max<int64_t>(0, time_ms)), &packet);
  } else {
    // Sequence and time only move forward (drops make gaps), so deltas are >= 0.
    PutVarint(f.sequence - previous_sequence_, &packet);
    PutVarint(static_cast<uint64_t>(std::max<int64_t>(0, time_ms - previous_time_ms_)), &packet);
  }
  BitWriter bits;
  bits.Bits(static_cast<uint64_t>(std::lround(std::clamp(f.confidence, 0.f, 1.f) * 15)), 4);
  for (int i = 0; i < layout_.num_values(); ++i) {
    const int64_t q = static_cast<int64_t>(std::llround(values[i] / layout_.steps[i]));
    if (key) {
      bits.SignedExpGolomb(q, kKeyOrder);
      magnitude_[i] = 0;
    } else {
      const int64_t residual = q - previous_[i];
      bits.SignedExpGolomb(residual, OrderFor(magnitude_[i]));
      UpdateMagnitude(residual, &magnitude_[i]);
    }
    previous_[i] = q;
  }
  packet += bits.Finish();
  coded_ = key ? 0 : coded_ + 1;
  previous_sequence_ = f.sequence;
  previous_time_ms_ = time_ms;
  since_key_ = key ? 0 : since_key_ + 1;
  force_key_ = false;
  return packet;
}

ParamDecoder::ParamDecoder(CodecLayout layout) : layout_(std::move(layout)) {
  layout_.Check();
  previous_.assign(layout_.num_values(), 0);
  magnitude_.assign(layout_.num_values(), 0);
}

bool ParamDecoder::Decode(const std::string& packet, FrameParams* out, std::string* why, double origin) {
  auto fail = [&](const std::string& w) {
    if (why) *why = w;
    return false;
  };
  if (packet.empty()) return fail("empty packet");
  const uint8_t head = static_cast<uint8_t>(packet[0]);
  if ((head >> 6) != kCodecVersion)
    return fail("codec version " + std::to_string(head >> 6) + ", expected " + std::to_string(kCodecVersion));
  if (head & 0x1f) return fail("reserved header bits set (not a headcast packet?)");
  const bool key = head & 0x20;
  size_t pos = 1;
  uint64_t chain = 0, seq = 0, time = 0;
  if (!GetVarint(packet, &pos, &chain) || !GetVarint(packet, &pos, &seq) || !GetVarint(packet, &pos, &time))
    return fail("truncated packet header");
  if (key != (chain == 0)) return fail("inconsistent key-frame marker");
  // Times stay far inside int64 milliseconds, so a key time plus any chain of
  // deltas cannot overflow (a peer chooses both).
  constexpr uint64_t kMaxTimeMs = uint64_t{1} << 45;  // about 1100 years
  if (time > kMaxTimeMs || (!key && previous_time_ms_ > static_cast<int64_t>(kMaxTimeMs - time)))
    return fail("capture time out of range");
  if (!key) {
    if (!have_reference_) return fail("delta frame without a reference; waiting for a key frame");
    if (chain != coded_ + 1) {
      have_reference_ = false;
      return fail("frame chain broken (missing packet); waiting for a key frame");
    }
  }
  BitReader bits(reinterpret_cast<const uint8_t*>(packet.data()) + pos, packet.size() - pos);
  uint64_t confidence = 0;
  if (!bits.Bits(4, &confidence)) return fail("truncated packet");
  std::vector<int64_t> q(layout_.num_values());
  std::vector<int> magnitude = magnitude_;
  std::vector<double> values(layout_.num_values());
  for (int i = 0; i < layout_.num_values(); ++i) {
    int64_t coded = 0;
    if (!bits.SignedExpGolomb(key ? kKeyOrder : OrderFor(magnitude[i]), &coded))
      return fail("truncated or corrupt packet");
    if (key) {
      q[i] = coded;
      magnitude[i] = 0;
    } else {
      if (std::llabs(coded) > (int64_t{1} << 40)) return fail("residual out of range");
      q[i] = previous_[i] + coded;
      UpdateMagnitude(coded, &magnitude[i]);
    }
    values[i] = static_cast<double>(q[i]) * layout_.steps[i];
    if (!(std::abs(values[i]) <= Limit(layout_, i))) return fail("value " + std::to_string(i) + " out of range");
  }
  if ((packet.size() - pos) * 8 - bits.bits_read() >= 8) return fail("trailing bytes after the frame");
  // Commit only a fully valid packet.
  previous_ = q;
  magnitude_ = magnitude;
  coded_ = chain;
  have_reference_ = true;
  FrameParams f;
  SetValues(layout_, values, &f);
  f.sequence = key ? seq : previous_sequence_ + seq;
  const int64_t time_ms = key ? static_cast<int64_t>(time) : previous_time_ms_ + static_cast<int64_t>(time);
  f.capture_time_s = origin + time_ms / 1000.0;
  f.confidence = static_cast<float>(confidence) / 15.f;
  previous_sequence_ = f.sequence;
  previous_time_ms_ = time_ms;
  *out = f;
  return true;
}

std::string PackPackets(const std::vector<std::string>& packets) {
  std::string out;
  for (const auto& p : packets) {
    PutVarint(p.size(), &out);
    out += p;
  }
  return out;
}

bool UnpackPackets(const std::string& payload, std::vector<std::string>* packets, std::string* why, int max_packets) {
  packets->clear();
  size_t pos = 0;
  while (pos < payload.size()) {
    uint64_t len = 0;
    if (!GetVarint(payload, &pos, &len) || len > payload.size() - pos) {
      if (why) *why = "truncated or corrupt frame batch";
      packets->clear();
      return false;
    }
    if (len == 0 || static_cast<int>(packets->size()) >= max_packets) {
      if (why)
        *why = len == 0 ? "an empty packet in the frame batch"
                        : "more than " + std::to_string(max_packets) + " packets in one message";
      packets->clear();
      return false;
    }
    packets->push_back(payload.substr(pos, len));
    pos += len;
  }
  return true;
}

}  // namespace headcast
