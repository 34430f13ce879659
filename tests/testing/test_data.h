// Where tests find ../shared/data (or HEADCAST_DATA), and how they skip without it.
#pragma once

#include <gtest/gtest.h>

#include <string>

namespace headcast::testing {

// The data folder: $HEADCAST_DATA, else <source>/../shared/data. Empty if absent.
std::string DataDir();
// A scratch folder unique to this test, created fresh.
std::string TempDir(const std::string& name);

}  // namespace headcast::testing

// Skips the current test with a clear message when the shared data is absent.
#define HEADCAST_REQUIRE_DATA(relative)                                                        \
  do {                                                                                         \
    if (::headcast::testing::DataDir().empty())                                                \
      GTEST_SKIP() << "shared data not found: set HEADCAST_DATA or put ../shared/data beside " \
                      "the checkout (needs " relative ")";                                     \
  } while (0)
