// systemd notifications over NOTIFY_SOCKET.
#include "common/core/service_notify.h"

#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <cstddef>
#include <cstdlib>
#include <cstring>

namespace headcast {

ServiceNotifier::ServiceNotifier() {
  if (const char* socket = std::getenv("NOTIFY_SOCKET")) socket_path_ = socket;
  // WATCHDOG_PID, when set, names the process systemd expects pings from.
  const char* pid = std::getenv("WATCHDOG_PID");
  const bool ours = !pid || std::atol(pid) == static_cast<long>(getpid());
  if (const char* usec = std::getenv("WATCHDOG_USEC"); usec && ours) watchdog_interval_s_ = std::atof(usec) / 2e6;
}

bool ServiceNotifier::Notify(const std::string& state) const {
  if (socket_path_.empty() || socket_path_.size() >= sizeof(sockaddr_un::sun_path)) return false;
  sockaddr_un address{};
  address.sun_family = AF_UNIX;
  std::memcpy(address.sun_path, socket_path_.data(), socket_path_.size());
  if (address.sun_path[0] == '@') address.sun_path[0] = '\0';  // abstract namespace
  const int fd = socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return false;
  const socklen_t length = static_cast<socklen_t>(offsetof(sockaddr_un, sun_path) + socket_path_.size());
  const bool sent = sendto(fd, state.data(), state.size(), MSG_NOSIGNAL, reinterpret_cast<sockaddr*>(&address),
                           length) == static_cast<ssize_t>(state.size());
  close(fd);
  return sent;
}

}  // namespace headcast
