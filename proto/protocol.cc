// Protocol helpers.
#include "proto/protocol.h"

#include <arpa/inet.h>
#include <netdb.h>
#include <netinet/in.h>

#include <algorithm>
#include <cstring>
#include <memory>
#include <sstream>
#include <stdexcept>

#include "common/core/zip_archive.h"

namespace headcast {
namespace {

bool IsLoopbackLiteral(const std::string& host) {
  in_addr v4{};
  if (inet_pton(AF_INET, host.c_str(), &v4) == 1) return (ntohl(v4.s_addr) >> 24) == 127;
  in6_addr v6{};
  return inet_pton(AF_INET6, host.c_str(), &v6) == 1 && IN6_IS_ADDR_LOOPBACK(&v6);
}

// "localhost" as the resolver sees it (/etc/hosts): loopback only, or no.
bool LocalhostIsLoopback() {
  addrinfo hints{};
  hints.ai_flags = AI_NUMERICSERV;
  addrinfo* found = nullptr;
  if (getaddrinfo("localhost", "1", &hints, &found) != 0 || !found) return false;
  std::unique_ptr<addrinfo, void (*)(addrinfo*)> guard(found, freeaddrinfo);
  for (const addrinfo* a = found; a; a = a->ai_next) {
    char text[INET6_ADDRSTRLEN] = {};
    const void* where = a->ai_family == AF_INET
                            ? static_cast<const void*>(&reinterpret_cast<const sockaddr_in*>(a->ai_addr)->sin_addr)
                            : static_cast<const void*>(&reinterpret_cast<const sockaddr_in6*>(a->ai_addr)->sin6_addr);
    if ((a->ai_family != AF_INET && a->ai_family != AF_INET6) || !inet_ntop(a->ai_family, where, text, sizeof text) ||
        !IsLoopbackLiteral(text))
      return false;
  }
  return true;
}

}  // namespace

bool ParseHostPort(const std::string& text, HostPort* out, std::string* why) {
  auto fail = [&](const std::string& w) {
    if (why) *why = "'" + text + "' is not host:port (" + w + ")";
    return false;
  };
  std::string host, port;
  if (!text.empty() && text[0] == '[') {
    const size_t close = text.find(']');
    if (close == std::string::npos) return fail("no ']' after an IPv6 address");
    host = text.substr(1, close - 1);
    if (close + 1 >= text.size() || text[close + 1] != ':') return fail("no port");
    port = text.substr(close + 2);
  } else {
    const size_t colon = text.rfind(':');
    if (colon == std::string::npos) return fail("no port");
    host = text.substr(0, colon);
    if (host.find(':') != std::string::npos) return fail("an IPv6 address needs brackets: [::1]:50051");
    port = text.substr(colon + 1);
  }
  if (host.empty()) return fail("no host");
  if (port.empty() || port.size() > 5 || !std::all_of(port.begin(), port.end(), ::isdigit))
    return fail("the port must be a number");
  const int p = std::stoi(port);
  if (p > 65535) return fail("ports end at 65535");
  if (out) *out = {host, p};
  return true;
}

std::vector<std::string> ReadTokenFile(const std::string& path) {
  const std::string bytes = ReadFileBytes(path);
  auto fail = [&](const std::string& why) { throw std::runtime_error(path + ": " + why); };
  if (bytes.size() > (1u << 20)) fail("too large for a token file");
  std::vector<std::string> tokens;
  std::istringstream in(bytes);
  int line_number = 0;
  for (std::string line; std::getline(in, line);) {
    ++line_number;
    const size_t first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos || line[first] == '#') continue;
    const std::string token = line.substr(first, line.find_last_not_of(" \t\r") - first + 1);
    const std::string where = "line " + std::to_string(line_number) + ": ";
    if (!std::all_of(token.begin(), token.end(), [](char c) { return c > ' ' && c < 127; }))
      fail(where + "a token is printable ASCII without blanks (is this a token file?)");
    if (token.size() < kMinTokenLength)
      fail(where + "a token needs at least " + std::to_string(kMinTokenLength) +
           " characters (make one with: openssl rand -hex 16)");
    tokens.push_back(token);
  }
  if (tokens.empty()) fail("no token in the file");
  return tokens;
}

bool IsLoopbackAddress(const std::string& host_port) {
  HostPort hp;
  std::string host = ParseHostPort(host_port, &hp, nullptr) ? hp.host : host_port;
  if (host.size() > 2 && host.front() == '[' && host.back() == ']') host = host.substr(1, host.size() - 2);
  if (host == "localhost") return LocalhostIsLoopback();
  return IsLoopbackLiteral(host);
}

}  // namespace headcast
