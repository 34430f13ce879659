// The parameter codec: round trips within the quantisation step, few bits,
// recovery after loss, and garbage refused without reading out of bounds.
#include "common/codec/param_codec.h"

#include <gtest/gtest.h>

#include <limits>
#include <random>

#include "common/codec/range_coder.h"
#include "common/codec/varint.h"
#include "common/headmodel/builtin_head.h"
#include "common/headmodel/synthetic_motion.h"

namespace headcast {
namespace {

const HeadModel& Model() {
  static const HeadModel m = MakeBuiltinHead();
  return m;
}

void ExpectWithinStep(const CodecLayout& l, const FrameParams& a, const FrameParams& b) {
  for (size_t k = 0; k < l.expression_components.size(); ++k) {
    const int c = l.expression_components[k];
    EXPECT_LE(std::abs(a.expression[c] - b.expression[c]), 0.5f * l.steps[k] + 1e-6f) << "expression " << c;
  }
  const Eigen::Vector3f* va[] = {&a.jaw, &a.neck, &a.left_eye, &a.right_eye, &a.cam_rotation, &a.cam_translation};
  const Eigen::Vector3f* vb[] = {&b.jaw, &b.neck, &b.left_eye, &b.right_eye, &b.cam_rotation, &b.cam_translation};
  const size_t e = l.expression_components.size();
  for (int g = 0; g < 6; ++g)
    for (int i = 0; i < 3; ++i) EXPECT_LE(std::abs((*va[g])[i] - (*vb[g])[i]), 0.5f * l.steps[e + 3 * g + i] + 1e-6f);
}

TEST(RangeCoder, IntegersRoundTripAndSkewedModelsCostLittle) {
  std::mt19937 rng(7);
  std::vector<int64_t> values = {0, 1, -1, 2, -7, 100, -100000, int64_t{1} << 35, -(int64_t{1} << 41)};
  for (int i = 0; i < 3000; ++i) values.push_back(rng() % 50 == 0 ? static_cast<int>(rng() % 9) - 4 : 0);
  RangeEncoder enc;
  IntModel model, bypass_check;
  for (int64_t v : values) model.Encode(v, &enc);
  for (int i = 0; i < 64; ++i) enc.EncodeBypass(i % 3 == 0);
  const std::string bytes = enc.Finish();
  RangeDecoder dec(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size());
  IntModel decoded;
  for (int64_t v : values) ASSERT_EQ(decoded.Decode(&dec), v);
  for (int i = 0; i < 64; ++i) ASSERT_EQ(dec.DecodeBypass(), i % 3 == 0) << i;
  EXPECT_LE(bytes.size(), dec.consumed());
  // Mostly zeros: far under a bit each (a prefix code spends at least one).
  EXPECT_LT(8.0 * bytes.size() / values.size(), 0.35);
  // Magnitudes beyond the longest the model codes are clamped, not wrapped.
  RangeEncoder e2;
  IntModel m2, d2;
  m2.Encode(std::numeric_limits<int64_t>::min(), &e2);
  const std::string b2 = e2.Finish();
  RangeDecoder r2(reinterpret_cast<const uint8_t*>(b2.data()), b2.size());
  EXPECT_EQ(d2.Decode(&r2), -((int64_t{1} << IntModel::kMaxBits) - 1));
}

TEST(RangeCoder, CarriesAndTerminationAreExactForEveryPrefix) {
  // Every prefix length of a random bit sequence under skewed models ends in
  // a packet that decodes to the same bits, though trailing zeros are dropped.
  std::mt19937 rng(11);
  for (int n = 0; n < 300; ++n) {
    std::vector<bool> bits;
    for (int i = 0; i < n; ++i) bits.push_back(rng() % 100 < (i % 7 == 0 ? 97 : 3));
    RangeEncoder enc;
    std::vector<BitModel> models(7);
    for (int i = 0; i < n; ++i) enc.Encode(bits[i], &models[i % 7]);
    const std::string bytes = enc.Finish();
    EXPECT_TRUE(bytes.empty() || bytes.back() != 0);
    RangeDecoder dec(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size());
    std::vector<BitModel> dm(7);
    for (int i = 0; i < n; ++i) ASSERT_EQ(dec.Decode(&dm[i % 7]), bits[i]) << "length " << n << " bit " << i;
  }
}

TEST(Varint, RoundTripsAndRefusesOverlongEncodings) {
  std::string varints;
  PutVarint(300, &varints);
  size_t pos = 0;
  uint64_t v;
  ASSERT_TRUE(GetVarint(varints, &pos, &v));
  EXPECT_EQ(v, 300u);
  pos = 0;
  EXPECT_FALSE(GetVarint(std::string("\xff\xff"), &pos, &v));
}

TEST(ParamCodec, StepsComeFromSensitivity) {
  const CodecLayout l = CodecLayout::FromModel(Model(), 2e-4);
  const int bins = OutlineOptions{}.bins;
  EXPECT_EQ(l.num_values(), Model().num_expression() + 21 + bins);  // and the skin colour and the outline
  EXPECT_EQ(CodecLayout::FromModel(Model(), 2e-4, {}, 30, false, 0).num_values(), Model().num_expression() + 18);
  // A step of any expression component moves the mesh by at most ~0.2 mm.
  for (size_t k = 0; k < l.expression_components.size(); ++k) {
    HeadModelParams p;
    p.expression = Eigen::VectorXd::Zero(Model().num_expression());
    p.expression[l.expression_components[k]] = l.steps[k];
    const float moved = (Model().Forward(p).vertices - Model().data().v_template).rowwise().norm().maxCoeff();
    EXPECT_LE(moved, 2.01e-4f);
    EXPECT_GT(moved, 1e-4f);
  }
  EXPECT_NEAR(l.steps[Model().num_expression() + 17], 2e-4f, 1e-9f);      // translation: the error itself
  EXPECT_NEAR(l.steps[Model().num_expression() + 20], 1.f / 255, 1e-9f);  // skin colour: an 8-bit level
  EXPECT_EQ(l.steps.back(), kOutlineStepMm);
}

TEST(ParamCodec, RoundTripWithinTheStepAndFewBits) {
  const CodecLayout l = CodecLayout::FromModel(Model());
  ParamEncoder enc(l);
  ParamDecoder dec(l);
  size_t bytes = 0;
  const int n = 300;
  for (int i = 0; i < n; ++i) {
    const FrameParams f = SyntheticTalkingHead(Model(), i);
    const std::string packet = enc.Encode(f);
    bytes += packet.size();
    FrameParams out;
    std::string why;
    ASSERT_TRUE(dec.Decode(packet, &out, &why)) << why;
    ExpectWithinStep(l, f, out);
    EXPECT_EQ(out.sequence, f.sequence);
    EXPECT_NEAR(out.capture_time_s, f.capture_time_s, 0.0006);
  }
  const double bits_per_frame = 8.0 * bytes / n;
  EXPECT_LT(bits_per_frame, 200);  // 31 values: a few bits each
}

// The skin colour travels within its step, a frame without one decodes
// without one, a layout without it (a peer that predates it) carries none, and
// a colour outside 0..1 is refused.
TEST(ParamCodec, TheSkinColourTravelsWhenTheLayoutSaysSo) {
  const CodecLayout with = CodecLayout::FromModel(Model());
  const CodecLayout without = CodecLayout::FromModel(Model(), 2e-4, {}, 30, false);
  ParamEncoder enc(with), enc_without(without);
  ParamDecoder dec(with), dec_without(without);
  for (int i = 0; i < 60; ++i) {
    FrameParams f = SyntheticTalkingHead(Model(), i);
    if (i % 10 != 9) f.skin_colour = Eigen::Vector3f(0.6f + 0.001f * i, 0.42f, 0.3f - 0.002f * i);
    FrameParams out;
    std::string why;
    ASSERT_TRUE(dec.Decode(enc.Encode(f), &out, &why)) << why;
    ExpectWithinStep(with, f, out);
    ASSERT_EQ(out.skin_colour.has_value(), f.skin_colour.has_value()) << i;
    if (f.skin_colour) EXPECT_LE((*out.skin_colour - *f.skin_colour).cwiseAbs().maxCoeff(), 0.5f / 255 + 1e-6f) << i;
    ASSERT_TRUE(dec_without.Decode(enc_without.Encode(f), &out, &why)) << why;
    EXPECT_FALSE(out.skin_colour.has_value());
  }
  FrameParams bright = SyntheticTalkingHead(Model(), 0);
  bright.skin_colour = Eigen::Vector3f(1.5f, 0.5f, 0.5f);  // encodable, refused on decode
  ParamEncoder e2(with);
  ParamDecoder d2(with);
  FrameParams out;
  std::string why;
  EXPECT_FALSE(d2.Decode(e2.Encode(bright), &out, &why));
  EXPECT_NE(why.find("out of range"), std::string::npos) << why;
}

// The outline travels within its step, a frame without one (or with an
// outline of another size) decodes without one, a layout without it carries
// none, and a negative value is refused.
TEST(ParamCodec, TheOutlineTravelsWhenTheLayoutSaysSo) {
  const CodecLayout with = CodecLayout::FromModel(Model());
  const CodecLayout without = CodecLayout::FromModel(Model(), 2e-4, {}, 30, true, 0);
  ASSERT_EQ(with.outline_bins, OutlineOptions{}.bins);
  ParamEncoder enc(with), enc_without(without);
  ParamDecoder dec(with), dec_without(without);
  for (int i = 0; i < 60; ++i) {
    FrameParams f = SyntheticTalkingHead(Model(), i);
    if (i % 10 != 9)
      for (int k = 0; k < with.outline_bins; ++k) f.outline.push_back(k == 3 ? kOutlineUnknown : 90.f + 0.37f * i + k);
    if (i == 25) f.outline.resize(5);  // not the layout's: travels as unknown
    FrameParams out;
    std::string why;
    ASSERT_TRUE(dec.Decode(enc.Encode(f), &out, &why)) << why;
    ExpectWithinStep(with, f, out);
    if (i % 10 == 9 || i == 25) {
      EXPECT_TRUE(out.outline.empty()) << i;
    } else {
      ASSERT_EQ(out.outline.size(), f.outline.size()) << i;
      for (size_t k = 0; k < f.outline.size(); ++k)
        EXPECT_NEAR(out.outline[k], f.outline[k], kOutlineStepMm / 2 + 1e-4);
      EXPECT_EQ(out.outline[3], kOutlineUnknown);
    }
    ASSERT_TRUE(dec_without.Decode(enc_without.Encode(f), &out, &why)) << why;
    EXPECT_TRUE(out.outline.empty());
  }
  FrameParams inward = SyntheticTalkingHead(Model(), 0);
  inward.outline.assign(with.outline_bins, 50.f);
  inward.outline[2] = -20.f;  // encodable, refused on decode
  ParamEncoder e2(with);
  ParamDecoder d2(with);
  FrameParams out;
  std::string why;
  EXPECT_FALSE(d2.Decode(e2.Encode(inward), &out, &why));
  EXPECT_NE(why.find("outline"), std::string::npos) << why;
  CodecLayout too_many = with;
  too_many.outline_bins = kMaxOutlineBins + 1;
  too_many.steps.resize(too_many.num_values(), kOutlineStepMm);
  EXPECT_THROW(too_many.Check(), std::invalid_argument);
}

TEST(ParamCodec, SubsetDecodesUnsentComponentsAsZero) {
  const CodecLayout l = CodecLayout::FromModel(Model(), 2e-4, {0, 8});
  ParamEncoder enc(l);
  ParamDecoder dec(l);
  FrameParams f = SyntheticTalkingHead(Model(), 5);
  f.expression.setConstant(0.5f);
  FrameParams out;
  ASSERT_TRUE(dec.Decode(enc.Encode(f), &out, nullptr));
  EXPECT_NEAR(out.expression[0], 0.5f, l.steps[0]);
  EXPECT_NEAR(out.expression[8], 0.5f, l.steps[1]);
  EXPECT_EQ(out.expression[3], 0.f);
}

TEST(ParamCodec, OutOfRangeComponentsAreRefusedBeforeTheBasisIsRead) {
  const int e = Model().num_expression();
  for (const std::vector<int>& bad : std::vector<std::vector<int>>{{100000}, {e}, {-5}, {0, 3, 3}}) {
    try {
      CodecLayout::FromModel(Model(), 2e-4, bad);
      ADD_FAILURE() << "accepted component " << bad.back();
    } catch (const std::invalid_argument& err) {
      EXPECT_NE(std::string(err.what()).find("expression component"), std::string::npos) << err.what();
    }
  }
}

TEST(ParamCodec, AbsurdCaptureTimesAreRefusedNotOverflowed) {
  const CodecLayout l = CodecLayout::FromModel(Model());
  ParamEncoder enc(l);
  ParamDecoder dec(l);
  FrameParams f = SyntheticTalkingHead(Model(), 0);
  f.capture_time_s = 0x1p62 / 1000;  // a key frame near 2^62 ms; a delta after it would overflow int64
  std::string why;
  EXPECT_FALSE(dec.Decode(enc.Encode(f), nullptr, &why));
  EXPECT_EQ(why, "capture time out of range");
  f.capture_time_s = 1000;  // an ordinary time still decodes
  enc.ForceKeyFrame();
  FrameParams out;
  EXPECT_TRUE(dec.Decode(enc.Encode(f), &out, &why)) << why;
}

TEST(ParamCodec, RecoversAtTheNextKeyFrameAfterALoss) {
  const CodecLayout l = CodecLayout::FromModel(Model(), 2e-4, {}, 10);
  ParamEncoder enc(l);
  ParamDecoder dec(l);
  std::vector<std::string> packets;
  for (int i = 0; i < 25; ++i) packets.push_back(enc.Encode(SyntheticTalkingHead(Model(), i)));
  FrameParams out;
  std::string why;
  int decoded = 0;
  for (int i = 0; i < 25; ++i) {
    if (i == 4) continue;  // lost
    if (dec.Decode(packets[i], &out, &why)) {
      ++decoded;
      EXPECT_TRUE(i < 4 || i >= 10) << i;
    } else {
      EXPECT_TRUE(i > 4 && i < 10) << i << ": " << why;
    }
  }
  EXPECT_EQ(decoded, 4 + 15);
}

TEST(ParamCodec, GarbageTruncationAndOutOfRangeAreRefused) {
  const CodecLayout l = CodecLayout::FromModel(Model());
  ParamEncoder enc(l);
  const std::string good = enc.Encode(SyntheticTalkingHead(Model(), 0));
  std::mt19937 rng(3);
  for (int trial = 0; trial < 2000; ++trial) {
    ParamDecoder dec(l);
    std::string p = good;
    if (trial % 3 == 0)
      p.resize(rng() % p.size());
    else if (trial % 3 == 1)
      p[rng() % p.size()] ^= static_cast<char>(1 + rng() % 255);
    else {
      p.assign(1 + rng() % 40, '\0');
      for (char& c : p) c = static_cast<char>(rng());
    }
    FrameParams out;
    std::string why;
    if (dec.Decode(p, &out, &why)) {
      EXPECT_TRUE(out.IsValid(&why)) << why;  // a flip may still decode: into a frame a renderer takes
    } else {
      EXPECT_FALSE(why.empty());
    }
  }
  FrameParams huge = SyntheticTalkingHead(Model(), 0);
  huge.cam_translation.z() = 500;  // 500 m: encodable, refused on decode
  ParamEncoder e2(l);
  ParamDecoder d2(l);
  std::string why;
  FrameParams out;
  EXPECT_FALSE(d2.Decode(e2.Encode(huge), &out, &why));
  EXPECT_NE(why.find("out of range"), std::string::npos);
  // Found by fuzzing: every value within its own range, but the rotations
  // turn by more than pi and the head sits behind the camera.
  CodecLayout small;
  small.num_expression = 13;
  for (int i = 0; i < 13; ++i) small.expression_components.push_back(i);
  small.steps.assign(13 + 18, 0.001f);
  ParamDecoder d3(small);
  EXPECT_FALSE(d3.Decode(std::string("\xa0\x00\x00\x01\x00\xd0\x08\xff\xff", 9), &out, &why));
  EXPECT_NE(why.find("decoded frame refused"), std::string::npos) << why;
  std::vector<std::string> packets;
  EXPECT_FALSE(UnpackPackets(std::string("\x05\x01", 2), &packets, &why));
  ASSERT_TRUE(UnpackPackets(PackPackets({good, good}), &packets, &why));
  EXPECT_EQ(packets.size(), 2u);
  // A megabyte of empty packets is refused at the first one, storing nothing.
  EXPECT_FALSE(UnpackPackets(std::string(1 << 20, '\0'), &packets, &why));
  EXPECT_NE(why.find("empty packet"), std::string::npos) << why;
  EXPECT_TRUE(packets.empty());
  EXPECT_FALSE(UnpackPackets(PackPackets(std::vector<std::string>(11, good)), &packets, &why, 10));
  EXPECT_NE(why.find("more than 10 packets"), std::string::npos) << why;
  EXPECT_TRUE(UnpackPackets(PackPackets(std::vector<std::string>(10, good)), &packets, &why, 10));
}

}  // namespace
}  // namespace headcast
