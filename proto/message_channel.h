// The transport seam: one session's bidirectional stream of protocol messages.
// The sender and receiver sessions speak Uplink/Downlink over this interface
// and know nothing of the transport; gRPC is one adapter per side
// (sender/grpc_uplink.h, receiver/session_server.h), the in-memory pair below
// serves tests, and another transport is one more adapter.
#pragma once

#include <condition_variable>
#include <deque>
#include <memory>
#include <mutex>
#include <string>
#include <utility>

#include "proto/headcast.pb.h"

namespace headcast {

template <typename Out, typename In>
class MessageChannel {
 public:
  virtual ~MessageChannel() = default;
  // False when the channel is closed or broken (the message was not sent).
  virtual bool Write(const Out& message) = 0;
  // Blocks for the next message; false at the end of the stream.
  virtual bool Read(In* message) = 0;
  // No more writes from this end: the peer's Read ends after what was sent.
  virtual void CloseWrites() = 0;
  // Abandons the stream both ways: a Read blocked on either end returns false.
  virtual void Cancel() = 0;
  // Once Read has returned false: why the stream ended, as the transport
  // says it (empty for a clean end).
  virtual std::string Finish() { return {}; }
};

// The sender's end writes Uplink and reads Downlink.
using UplinkChannel = MessageChannel<v1::Uplink, v1::Downlink>;

// The receiver's end writes Downlink and reads Uplink, and says which bearer
// token the transport carried outside the messages (HTTP/2 metadata), if any.
class DownlinkChannel : public MessageChannel<v1::Downlink, v1::Uplink> {
 public:
  virtual std::string bearer_token() const { return {}; }
};

// A connected pair of in-memory ends (tests, in-process loopback). Messages
// are copied; nothing is lost or reordered.
struct InMemoryChannelPair {
  std::unique_ptr<UplinkChannel> sender;
  std::unique_ptr<DownlinkChannel> receiver;
};
InMemoryChannelPair MakeInMemoryChannelPair(std::string bearer_token = {});

}  // namespace headcast
