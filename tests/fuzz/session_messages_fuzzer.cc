// libFuzzer target: what a receiver reads from a peer before and during a
// session. The bytes are parsed as an Uplink message; a Hello's parameter
// layout goes through FromProto (and, when accepted, a decoder is made for
// it), a Frames payload through UnpackPackets and the decoder. The same bytes
// are opened as a datagram (under a key with their own connection id, so the
// authentication runs). Nothing may crash, hang or read out of bounds; an
// accepted layout must pass its Check; no forged datagram may open.
#include <cstdint>
#include <cstdlib>
#include <string>
#include <vector>

#include "common/codec/param_codec.h"
#include "proto/convert.h"
#include "proto/datagram.h"
#include "proto/headcast.pb.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  {
    const std::string bytes(reinterpret_cast<const char*>(data), size);
    static headcast::DatagramKey key = headcast::DatagramKey::Random();
    uint32_t id = 0, counter = 0;
    std::string plaintext, why;
    if (headcast::PeekDatagramConnection(bytes, headcast::DatagramDirection::kUplink, &id)) {
      key.connection_id = id;
      if (headcast::OpenDatagram(key, headcast::DatagramDirection::kUplink, bytes, &counter, &plaintext, &why))
        std::abort();  // a forgery opened
    }
  }
  headcast::v1::Uplink up;
  if (!up.ParseFromArray(data, static_cast<int>(size))) return 0;
  if (up.has_hello()) {
    headcast::CodecLayout layout;
    std::string why;
    if (!headcast::FromProto(up.hello().layout(), &layout, &why)) return 0;
    layout.Check();  // throws (and so aborts the fuzzer) if FromProto let a bad layout through
    headcast::ParamDecoder decoder(layout);
    headcast::FrameParams f;
    decoder.Decode(up.hello().sender_name(), &f, &why);
  }
  if (up.has_frames()) {
    static const headcast::CodecLayout layout = [] {
      headcast::CodecLayout l;
      l.num_expression = 13;
      for (int i = 0; i < 13; ++i) l.expression_components.push_back(i);
      l.steps.assign(13 + 18, 0.001f);
      return l;
    }();
    headcast::ParamDecoder decoder(layout);
    std::vector<std::string> packets;
    std::string why;
    if (!headcast::UnpackPackets(up.frames().payload(), &packets, &why)) return 0;
    if (packets.size() > 1000) std::abort();  // the unpacker's bound
    for (const std::string& p : packets) {
      headcast::FrameParams f;
      if (decoder.Decode(p, &f, &why) && !f.IsValid(&why)) std::abort();
    }
  }
  return 0;
}
