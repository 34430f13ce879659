// Protocol constants and address rules shared by sender and receiver.
#pragma once

#include <cstdint>
#include <string>

namespace headcast {

constexpr uint32_t kProtocolVersion = 1;

// True for 127.0.0.0/8, ::1 and "localhost" (with or without a port): the only
// addresses where plaintext is allowed.
bool IsLoopbackAddress(const std::string& host_port);

}  // namespace headcast
