// The parameter codec.
#include "common/codec/param_codec.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "common/codec/varint.h"
#include "common/core/options.h"

namespace headcast {
namespace {

// The packet's first byte: version (2 bits), key flag, then the low bits of
// the frame's place in its chain since the key frame (0 in a key frame): a
// decoder that missed a packet sees the gap instead of decoding garbage.
constexpr int kChainMask = 0x1f;
// Capture times stay far inside int64 milliseconds, so a key time plus any
// chain of deltas cannot overflow (a peer chooses both).
constexpr int64_t kMaxTimeMs = int64_t{1} << 45;  // about 1100 years
constexpr int64_t kMaxSequenceStep = int64_t{1} << 40;
constexpr int64_t kMaxQuantised = int64_t{1} << 40;  // |value / step| the encoder sends at most
constexpr int kConfidenceLevels = 15;

// The coded values of a frame, in layout order.
std::vector<double> Values(const CodecLayout& layout, const FrameParams& f) {
  std::vector<double> v;
  v.reserve(layout.num_values());
  for (int c : layout.expression_components) v.push_back(c < f.expression.size() ? f.expression[c] : 0.0);
  for (const Eigen::Vector3f* r : {&f.jaw, &f.neck, &f.left_eye, &f.right_eye, &f.cam_rotation, &f.cam_translation})
    for (int i = 0; i < 3; ++i) v.push_back((*r)[i]);
  if (layout.skin_colour)
    for (int i = 0; i < 3; ++i) v.push_back(f.skin_colour ? (*f.skin_colour)[i] : 0.0);
  // An outline of another size than the layout's travels as unknown.
  const bool outline = static_cast<int>(f.outline.size()) == layout.outline_bins;
  for (int i = 0; i < layout.outline_bins; ++i) v.push_back(outline ? f.outline[i] : kOutlineUnknown);
  return v;
}

void SetValues(const CodecLayout& layout, const std::vector<double>& v, FrameParams* f) {
  f->expression = Eigen::VectorXf::Zero(layout.num_expression);
  size_t k = 0;
  for (int c : layout.expression_components) f->expression[c] = static_cast<float>(v[k++]);
  for (Eigen::Vector3f* r : {&f->jaw, &f->neck, &f->left_eye, &f->right_eye, &f->cam_rotation, &f->cam_translation})
    for (int i = 0; i < 3; ++i) (*r)[i] = static_cast<float>(v[k++]);
  f->skin_colour.reset();
  if (layout.skin_colour) {
    const Eigen::Vector3f rgb(static_cast<float>(v[k]), static_cast<float>(v[k + 1]), static_cast<float>(v[k + 2]));
    if (rgb != Eigen::Vector3f::Zero()) f->skin_colour = rgb;  // 0, 0, 0: not measured
    k += 3;
  }
  f->outline.clear();
  bool measured = false;
  for (int i = 0; i < layout.outline_bins; ++i) measured = measured || v[k + i] != kOutlineUnknown;
  if (measured)  // all unknown: not measured
    for (int i = 0; i < layout.outline_bins; ++i) f->outline.push_back(static_cast<float>(v[k + i]));
}

// Largest magnitude a value may decode to (garbage and hostile packets are refused).
double Limit(const CodecLayout& layout, int index) {
  const int e = static_cast<int>(layout.expression_components.size());
  if (index < e) return 10.0;                            // expression coefficients
  if (index < e + 15) return M_PI;                       // rotations, radians
  if (index < e + 18) return 20.0;                       // translation, metres
  if (layout.skin_colour && index < e + 21) return 1.0;  // skin colour
  return kMaxOutlineMm;                                  // outline, mm
}

}  // namespace

void CodecLayout::Check() const {
  OptionsCheck c("CodecLayout");
  c.InRange("num_expression", num_expression, 0, 4096).InRange("key_frame_interval", key_frame_interval, 1, 100000);
  c.InRange("outline_bins", outline_bins, 0, kMaxOutlineBins);
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

CodecLayout CodecLayout::FromModel(const HeadModel& model, double err, std::vector<int> components, int key_interval,
                                   bool skin_colour, int outline_bins) {
  CodecLayout l;
  l.skin_colour = skin_colour;
  l.outline_bins = outline_bins;
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
  if (skin_colour)
    for (int i = 0; i < 3; ++i) l.steps.push_back(1.f / 255);
  for (int i = 0; i < outline_bins; ++i) l.steps.push_back(kOutlineStepMm);
  l.Check();
  return l;
}

CodecState::CodecState(int num_values) : previous(num_values, 0), value_models(num_values) {}

void CodecState::Reset() {
  std::fill(value_models.begin(), value_models.end(), IntModel{});
  key_values = sequence_step = time_step = confidence = IntModel{};
  coded = 0;
  sequence_delta = time_delta_ms = confidence_level = 0;
}

ParamEncoder::ParamEncoder(CodecLayout layout)
    : layout_(std::move(layout)), state_((layout_.Check(), layout_.num_values())) {}

std::string ParamEncoder::Encode(const FrameParams& f, double origin) {
  const bool key = force_key_ || since_key_ >= layout_.key_frame_interval - 1;
  const std::vector<double> values = Values(layout_, f);
  const double t = std::round((f.capture_time_s - origin) * 1000);
  const int64_t time_ms = std::isfinite(t) ? static_cast<int64_t>(std::clamp(t, 0.0, 0x1p62)) : 0;
  const int64_t level =
      std::lround(std::clamp(std::isfinite(f.confidence) ? f.confidence : 0.f, 0.f, 1.f) * kConfidenceLevels);
  CodecState& s = state_;
  const uint64_t chain = key ? 0 : s.coded + 1;
  std::string packet(1, static_cast<char>((kCodecVersion << 6) | (key ? 0x20 : 0) | (chain & kChainMask)));
  RangeEncoder rc;
  if (key) {
    s.Reset();
    PutVarint(f.sequence, &packet);
    PutVarint(static_cast<uint64_t>(time_ms), &packet);
    s.confidence.Encode(level, &rc);
    s.previous_sequence = f.sequence;
    s.previous_time_ms = time_ms;
  } else {
    // Sequence and time only move forward (drops make gaps); each step is
    // predicted by the last one (a camera's steady rate costs next to nothing).
    const int64_t sequence_step =
        f.sequence >= s.previous_sequence
            ? static_cast<int64_t>(std::min<uint64_t>(f.sequence - s.previous_sequence, kMaxSequenceStep))
            : 0;
    const int64_t time_step = std::clamp<int64_t>(time_ms - s.previous_time_ms, 0, kMaxTimeMs);
    s.sequence_step.Encode(sequence_step - s.sequence_delta, &rc);
    s.time_step.Encode(time_step - s.time_delta_ms, &rc);
    s.confidence.Encode(level - s.confidence_level, &rc);
    s.sequence_delta = sequence_step;
    s.time_delta_ms = time_step;
    // What the decoder will reconstruct, even where the input went backwards.
    s.previous_sequence += static_cast<uint64_t>(sequence_step);
    s.previous_time_ms += time_step;
  }
  s.confidence_level = level;
  for (int i = 0; i < layout_.num_values(); ++i) {
    const double x = values[i] / layout_.steps[i];
    const int64_t q =
        std::isfinite(x)
            ? static_cast<int64_t>(std::llround(std::clamp(x, -double(kMaxQuantised), double(kMaxQuantised))))
            : 0;
    if (key)
      s.key_values.Encode(q, &rc);
    else
      s.value_models[i].Encode(q - s.previous[i], &rc);
    s.previous[i] = q;
  }
  packet += rc.Finish();
  s.coded = chain;
  since_key_ = key ? 0 : since_key_ + 1;
  force_key_ = false;
  return packet;
}

ParamDecoder::ParamDecoder(CodecLayout layout)
    : layout_(std::move(layout)), state_((layout_.Check(), layout_.num_values())) {}

bool ParamDecoder::Decode(const std::string& packet, FrameParams* out, std::string* why, double origin) {
  auto fail = [&](const std::string& w) {
    if (why) *why = w;
    return false;
  };
  if (packet.empty()) return fail("empty packet");
  const uint8_t head = static_cast<uint8_t>(packet[0]);
  if ((head >> 6) != kCodecVersion)
    return fail("codec version " + std::to_string(head >> 6) + ", expected " + std::to_string(kCodecVersion));
  const bool key = head & 0x20;
  const uint64_t chain_bits = head & kChainMask;
  CodecState next = state_;  // committed only when the whole packet is valid
  size_t pos = 1;
  if (key) {
    if (chain_bits != 0) return fail("reserved header bits set (not a headcast packet?)");
    uint64_t sequence = 0, time = 0;
    if (!GetVarint(packet, &pos, &sequence) || !GetVarint(packet, &pos, &time)) return fail("truncated packet header");
    if (time > static_cast<uint64_t>(kMaxTimeMs)) return fail("capture time out of range");
    next.Reset();
    next.previous_sequence = sequence;
    next.previous_time_ms = static_cast<int64_t>(time);
  } else {
    if (!have_reference_) return fail("delta frame without a reference; waiting for a key frame");
    if (chain_bits != ((next.coded + 1) & kChainMask)) {
      have_reference_ = false;
      return fail("frame chain broken (missing packet); waiting for a key frame");
    }
  }
  RangeDecoder rc(reinterpret_cast<const uint8_t*>(packet.data()) + pos, packet.size() - pos);
  int64_t level = 0;
  if (key) {
    level = next.confidence.Decode(&rc);
  } else {
    const int64_t sequence_step = next.sequence_delta + next.sequence_step.Decode(&rc);
    const int64_t time_step = next.time_delta_ms + next.time_step.Decode(&rc);
    level = next.confidence_level + next.confidence.Decode(&rc);
    if (sequence_step < 0 || sequence_step > kMaxSequenceStep) return fail("sequence step out of range");
    if (time_step < 0 || time_step > kMaxTimeMs - next.previous_time_ms) return fail("capture time out of range");
    next.sequence_delta = sequence_step;
    next.time_delta_ms = time_step;
    next.previous_sequence += static_cast<uint64_t>(sequence_step);
    next.previous_time_ms += time_step;
  }
  if (level < 0 || level > kConfidenceLevels) return fail("confidence out of range");
  next.confidence_level = level;
  std::vector<double> values(layout_.num_values());
  for (int i = 0; i < layout_.num_values(); ++i) {
    const int64_t q = key ? next.key_values.Decode(&rc) : next.previous[i] + next.value_models[i].Decode(&rc);
    values[i] = static_cast<double>(q) * layout_.steps[i];
    if (!(std::abs(values[i]) <= Limit(layout_, i))) return fail("value " + std::to_string(i) + " out of range");
    next.previous[i] = q;
  }
  if (packet.size() - pos > rc.consumed()) return fail("trailing bytes after the frame");
  FrameParams f;
  SetValues(layout_, values, &f);
  f.sequence = next.previous_sequence;
  f.capture_time_s = origin + next.previous_time_ms / 1000.0;
  f.confidence = static_cast<float>(level) / kConfidenceLevels;
  // Each value within its own range does not make a frame: a rotation whose
  // components are each <= pi may still turn by more, a head may sit behind
  // the camera. What the stream hands on must be what a renderer accepts.
  std::string invalid;
  if (!f.IsValid(&invalid)) return fail("decoded frame refused: " + invalid);
  next.coded = key ? 0 : next.coded + 1;
  state_ = std::move(next);
  have_reference_ = true;
  if (out) *out = f;
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
