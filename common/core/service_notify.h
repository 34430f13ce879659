// systemd's service notifications (sd_notify's datagram protocol, without
// libsystemd): READY=1 once a service serves, WATCHDOG=1 while it is alive.
// Outside systemd (no NOTIFY_SOCKET) every call does nothing.
#pragma once

#include <string>

namespace headcast {

class ServiceNotifier {
 public:
  ServiceNotifier();  // reads NOTIFY_SOCKET and WATCHDOG_USEC
  // Sends `state` ("READY=1", "WATCHDOG=1", "STATUS=..."); false if it could not.
  bool Notify(const std::string& state) const;
  bool active() const { return !socket_path_.empty(); }
  // How often the watchdog wants to hear from us (half its timeout), seconds; 0: no watchdog.
  double watchdog_interval_s() const { return watchdog_interval_s_; }

 private:
  std::string socket_path_;  // "@..." for an abstract socket
  double watchdog_interval_s_ = 0;
};

}  // namespace headcast
