// The sender's gRPC adapter: a channel to the receiver (TLS or plaintext on
// loopback, keepalive, fast reconnects, the bearer token as metadata) and one
// bidirectional Session stream per connection attempt, as an UplinkChannel.
#pragma once

#include <memory>

#include "sender/session_client.h"

namespace headcast {

// Throws naming the file when TLS material cannot be read.
std::unique_ptr<UplinkConnector> MakeGrpcUplinkConnector(const SenderOptions& options);

}  // namespace headcast
