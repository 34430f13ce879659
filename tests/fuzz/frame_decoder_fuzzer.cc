// libFuzzer target: the receiver's frame decoding path (batch unpacking and
// ParamCodec decoding) on arbitrary bytes. It must never crash, hang or read
// out of bounds, and whatever it accepts must be finite and in range.
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <vector>

#include "common/codec/param_codec.h"

namespace {
headcast::CodecLayout Layout() {
  headcast::CodecLayout l;
  l.num_expression = 13;
  for (int i = 0; i < 13; ++i) l.expression_components.push_back(i);
  l.steps.assign(13, 0.01f);
  l.steps.resize(13 + 15, 0.002f);
  l.steps.resize(13 + 18, 0.0002f);
  l.key_frame_interval = 30;
  return l;
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const headcast::CodecLayout layout = Layout();
  headcast::ParamDecoder decoder(layout);
  const std::string payload(reinterpret_cast<const char*>(data), size);
  std::vector<std::string> packets;
  std::string why;
  // Either a whole Frames payload, or (when it does not unpack) one raw packet.
  if (!headcast::UnpackPackets(payload, &packets, &why)) packets = {payload};
  for (const std::string& p : packets) {
    headcast::FrameParams f;
    if (!decoder.Decode(p, &f, &why)) continue;
    if (!f.expression.allFinite() || !f.cam_translation.allFinite() || !f.cam_rotation.allFinite()) std::abort();
    if (f.expression.size() != 13 || f.expression.cwiseAbs().maxCoeff() > 10.f + 1e-3f) std::abort();
    if (f.cam_translation.cwiseAbs().maxCoeff() > 20.f + 1e-3f) std::abort();
  }
  return 0;
}
