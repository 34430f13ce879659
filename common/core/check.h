// HEADCAST_CHECK: the error tier for broken invariants — a bug in headcast,
// not bad input. A failed check prints the condition, the place and the
// streamed context, then aborts. Bad configuration and bad files throw with
// a clear message instead; expected per-frame failures are statuses.
#pragma once

#include <sstream>

namespace headcast::internal {

class CheckFailure {
 public:
  CheckFailure(const char* file, int line, const char* condition);
  [[noreturn]] ~CheckFailure();
  std::ostream& stream() { return message_; }

 private:
  std::ostringstream message_;
};

}  // namespace headcast::internal

// Usage: HEADCAST_CHECK(index < size) << "index " << index;
#define HEADCAST_CHECK(condition) \
  while (!(condition)) ::headcast::internal::CheckFailure(__FILE__, __LINE__, #condition).stream()
