// The one main of every headcast test binary: seeds all random generators so runs repeat.
#include <ATen/Context.h>
#include <gtest/gtest.h>

#include <cstdlib>
#include <opencv2/core.hpp>

#include "common/core/log.h"

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  constexpr unsigned kSeed = 20241122;
  std::srand(kSeed);
  cv::theRNG().state = kSeed;
  at::manual_seed(kSeed);
  headcast::InitLogging("warn");
  return RUN_ALL_TESTS();
}
