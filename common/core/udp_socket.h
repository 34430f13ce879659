// A UDP socket for the frames' datagram path: bound (the receiver) or
// connected to one peer (the sender), IPv4 or IPv6, names resolved once.
#pragma once

#include <string>

namespace headcast {

class UdpSocket {
 public:
  // Bound to host:port (port 0: any free port). Throws std::runtime_error
  // naming the address when it cannot be resolved or bound.
  static UdpSocket Bind(const std::string& host, int port);
  // Connected to host:port: Send goes there, and only its datagrams are received.
  static UdpSocket Connect(const std::string& host, int port);

  UdpSocket(UdpSocket&& other) noexcept;
  UdpSocket& operator=(UdpSocket&& other) noexcept;
  UdpSocket(const UdpSocket&) = delete;
  UdpSocket& operator=(const UdpSocket&) = delete;
  ~UdpSocket();

  int port() const;  // the local port
  // One datagram; false when the system refuses it now (a full buffer, no
  // route, the peer's port closed): a datagram path loses, it never blocks.
  bool Send(const std::string& datagram);
  // To a peer as Receive reported it (a bound socket answering its senders).
  bool SendTo(const std::string& peer, const std::string& datagram);
  enum class Received { kDatagram, kTimeout, kTooLarge, kError };
  // Waits up to timeout_ms for one datagram of at most max_bytes; a larger
  // one is consumed and reported kTooLarge (never truncated into *out).
  // *peer, if given, gets the sender's address (opaque bytes for SendTo).
  Received Receive(std::string* out, size_t max_bytes, int timeout_ms, std::string* peer = nullptr);

 private:
  explicit UdpSocket(int fd) : fd_(fd) {}
  int fd_ = -1;
};

}  // namespace headcast
