// Protocol constants and address rules shared by sender and receiver.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace headcast {

constexpr uint32_t kProtocolVersion = 1;

// "host:port" or "[v6]:port". The port must be given (gRPC would quietly take
// 443 without one) and lie in 0..65535 (0: any free port, for listening).
// False with the reason in *why otherwise.
struct HostPort {
  std::string host;
  int port = -1;
};
bool ParseHostPort(const std::string& text, HostPort* out, std::string* why);

// True for 127.0.0.0/8 and ::1 written as addresses, and for "localhost" when
// it resolves to loopback addresses only (with or without a port): the only
// places where plaintext is allowed. Any other name is false, even one that
// begins with "127." or resolves to 127.0.0.1 today.
bool IsLoopbackAddress(const std::string& host_port);

// Bearer tokens are secrets a person generates (openssl rand -hex 16): at
// least this long, printable, no spaces.
constexpr size_t kMinTokenLength = 16;

// The tokens of a token file, one per line: CR/LF endings, surrounding
// blanks, empty lines and "#" comment lines are allowed and dropped. Throws
// std::runtime_error naming the file and line for a short or unprintable
// token, a binary file, or a file without any token.
std::vector<std::string> ReadTokenFile(const std::string& path);

}  // namespace headcast
