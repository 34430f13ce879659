// The sender's gRPC adapter: a channel to the receiver (TLS or plaintext on
// loopback, keepalive, fast reconnects, the bearer token as metadata) and one
// bidirectional Session stream per connection attempt, as an UplinkChannel.
#pragma once

#include <memory>
#include <string>

#include "sender/session_client.h"

namespace headcast {

// Throws naming the file when TLS material cannot be read.
std::unique_ptr<UplinkConnector> MakeGrpcUplinkConnector(const SenderOptions& options);

// Asks the receiver at options.target for its health (grpc.health.v1 Check,
// over the same channel a session uses: TLS or plaintext on loopback) within
// `timeout_s`. Returns "SERVING", "NOT_SERVING", ... or why it could not ask
// ("unreachable: ..."); the caller decides what is healthy.
std::string CheckReceiverHealth(const SenderOptions& options, double timeout_s);

}  // namespace headcast
