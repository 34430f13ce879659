// What the session tests share: the built-in head, its codec layout, the
// receiver's avatar table, and waiting for a condition with a deadline.
#pragma once

#include <chrono>
#include <functional>
#include <map>
#include <string>
#include <thread>

#include "common/codec/param_codec.h"
#include "common/headmodel/builtin_head.h"
#include "receiver/receiver_sessions.h"

namespace headcast::testing {

inline const HeadModel& SessionModel() {
  static const HeadModel m = MakeBuiltinHead();
  return m;
}

inline const CodecLayout& SessionLayout() {
  static const CodecLayout l = CodecLayout::FromModel(SessionModel());
  return l;
}

inline std::map<std::string, AvatarEntry> SessionAvatars() {
  return {{"demo", {SessionModel().fingerprint(), SessionModel().num_expression()}}};
}

inline bool WaitFor(const std::function<bool()>& condition, double seconds) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (std::chrono::steady_clock::now() < deadline) {
    if (condition()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return condition();
}

}  // namespace headcast::testing
