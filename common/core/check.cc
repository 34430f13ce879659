// Failed invariant checks.
#include "common/core/check.h"

#include <cstdio>
#include <cstdlib>

namespace headcast::internal {

CheckFailure::CheckFailure(const char* file, int line, const char* condition) {
  message_ << file << ":" << line << ": check failed: " << condition << " ";
}

CheckFailure::~CheckFailure() {
  std::fprintf(stderr, "headcast internal error (please report): %s\n", message_.str().c_str());
  std::fflush(stderr);
  std::abort();
}

}  // namespace headcast::internal
