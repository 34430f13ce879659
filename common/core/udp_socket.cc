// UDP sockets over the POSIX API.
#include "common/core/udp_socket.h"

#include <netdb.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <stdexcept>

namespace headcast {
namespace {

// Brackets of "[::1]" are the caller's business: host is a bare name or address.
addrinfo* Resolve(const std::string& host, int port, bool passive) {
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_DGRAM;
  hints.ai_flags = passive ? AI_PASSIVE : 0;
  addrinfo* result = nullptr;
  const std::string service = std::to_string(port);
  const int rc = getaddrinfo(host.empty() ? nullptr : host.c_str(), service.c_str(), &hints, &result);
  if (rc != 0) throw std::runtime_error("udp: cannot resolve " + host + ":" + service + ": " + gai_strerror(rc));
  return result;
}

template <typename Use>
int OpenFirst(const std::string& host, int port, bool passive, Use use, const char* what) {
  addrinfo* list = Resolve(host, port, passive);
  std::string last_error = "no address";
  int fd = -1;
  for (addrinfo* a = list; a && fd < 0; a = a->ai_next) {
    fd = socket(a->ai_family, a->ai_socktype | SOCK_CLOEXEC, a->ai_protocol);
    if (fd < 0) {
      last_error = std::strerror(errno);
      continue;
    }
    if (use(fd, a->ai_addr, a->ai_addrlen) != 0) {
      last_error = std::strerror(errno);
      close(fd);
      fd = -1;
    }
  }
  freeaddrinfo(list);
  if (fd < 0)
    throw std::runtime_error(std::string("udp: cannot ") + what + " " + host + ":" + std::to_string(port) + ": " +
                             last_error);
  return fd;
}

}  // namespace

UdpSocket UdpSocket::Bind(const std::string& host, int port) {
  return UdpSocket(OpenFirst(host, port, true, ::bind, "bind"));
}

UdpSocket UdpSocket::Connect(const std::string& host, int port) {
  return UdpSocket(OpenFirst(host, port, false, ::connect, "connect to"));
}

UdpSocket::UdpSocket(UdpSocket&& other) noexcept : fd_(other.fd_) { other.fd_ = -1; }

UdpSocket& UdpSocket::operator=(UdpSocket&& other) noexcept {
  if (this != &other) {
    if (fd_ >= 0) close(fd_);
    fd_ = other.fd_;
    other.fd_ = -1;
  }
  return *this;
}

UdpSocket::~UdpSocket() {
  if (fd_ >= 0) close(fd_);
}

int UdpSocket::port() const {
  sockaddr_storage address{};
  socklen_t length = sizeof(address);
  if (getsockname(fd_, reinterpret_cast<sockaddr*>(&address), &length) != 0) return -1;
  char service[NI_MAXSERV];
  if (getnameinfo(reinterpret_cast<sockaddr*>(&address), length, nullptr, 0, service, sizeof(service),
                  NI_NUMERICSERV) != 0)
    return -1;
  return std::atoi(service);
}

bool UdpSocket::Send(const std::string& datagram) {
  return send(fd_, datagram.data(), datagram.size(), MSG_DONTWAIT | MSG_NOSIGNAL) ==
         static_cast<ssize_t>(datagram.size());
}

bool UdpSocket::SendTo(const std::string& peer, const std::string& datagram) {
  if (peer.empty() || peer.size() > sizeof(sockaddr_storage)) return false;
  sockaddr_storage address{};
  std::memcpy(&address, peer.data(), peer.size());
  return sendto(fd_, datagram.data(), datagram.size(), MSG_DONTWAIT | MSG_NOSIGNAL,
                reinterpret_cast<const sockaddr*>(&address),
                static_cast<socklen_t>(peer.size())) == static_cast<ssize_t>(datagram.size());
}

UdpSocket::Received UdpSocket::Receive(std::string* out, size_t max_bytes, int timeout_ms, std::string* peer) {
  pollfd p{fd_, POLLIN, 0};
  const int ready = poll(&p, 1, timeout_ms);
  if (ready == 0 || (ready < 0 && errno == EINTR)) return Received::kTimeout;
  if (ready < 0) return Received::kError;
  out->resize(max_bytes + 1);  // one byte more than allowed: a larger datagram shows as truncated
  sockaddr_storage from{};
  socklen_t from_length = sizeof(from);
  const ssize_t n = recvfrom(fd_, out->data(), out->size(), MSG_DONTWAIT | MSG_TRUNC,
                             reinterpret_cast<sockaddr*>(&from), &from_length);
  if (n < 0) {
    out->clear();
    return errno == EAGAIN || errno == EWOULDBLOCK || errno == ECONNREFUSED ? Received::kTimeout : Received::kError;
  }
  if (static_cast<size_t>(n) > max_bytes) {
    out->clear();
    return Received::kTooLarge;
  }
  out->resize(static_cast<size_t>(n));
  if (peer) peer->assign(reinterpret_cast<const char*>(&from), std::min<size_t>(from_length, sizeof(from)));
  return Received::kDatagram;
}

}  // namespace headcast
