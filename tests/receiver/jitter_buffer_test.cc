// Jitter buffer: playout delay, reordering, late drops, loss counting, interpolation.
#include "receiver/jitter_buffer.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>

namespace headcast {
namespace {

FrameParams Frame(uint64_t seq, double t, float value) {
  FrameParams f;
  f.sequence = seq;
  f.capture_time_s = t;
  f.expression = Eigen::VectorXf::Constant(3, value);
  f.cam_translation = Eigen::Vector3f(0, 0, 0.6f);
  f.neck = Eigen::Vector3f(0, value, 0);
  return f;
}

TEST(JitterBuffer, PlaysOutAfterTheDelayAndInterpolates) {
  JitterBufferOptions o;
  o.target_delay_s = 0.1;
  JitterBuffer jb(o);
  // Sender clock starts at 1000 s; frames arrive 20 ms after capture on a receiver clock starting at 5 s.
  for (int i = 0; i < 10; ++i) jb.Push(Frame(i, 1000 + i / 30.0, static_cast<float>(i)), 5 + i / 30.0 + 0.02);
  EXPECT_FALSE(jb.Sample(5.0).has_value());  // before the first playout time
  EXPECT_NEAR(jb.PlayoutTime(1000), 5.12, 1e-9);
  auto f = jb.Sample(5.12 + 1.5 / 30.0);  // halfway between frames 1 and 2
  ASSERT_TRUE(f.has_value());
  EXPECT_NEAR(f->expression[0], 1.5f, 1e-4);
  EXPECT_NEAR(f->neck.y(), 1.5f, 1e-4);  // slerp about one axis interpolates the angle
}

TEST(JitterBuffer, ReordersDropsLateAndCountsLoss) {
  JitterBuffer jb;
  jb.Push(Frame(0, 0.0, 0), 0.01);
  jb.Push(Frame(2, 2 / 30.0, 2), 0.08);
  jb.Push(Frame(1, 1 / 30.0, 1), 0.09);  // out of order, still in time
  jb.Push(Frame(1, 1 / 30.0, 1), 0.09);  // duplicate
  EXPECT_EQ(jb.stats().received, 3u);
  EXPECT_EQ(jb.stats().duplicate, 1u);
  auto f = jb.Sample(0.01 + 0.1 + 1 / 30.0);
  ASSERT_TRUE(f.has_value());
  EXPECT_NEAR(f->expression[0], 1.f, 1e-4);
  jb.Push(Frame(5, 5 / 30.0, 5), 0.2);
  (void)jb.Sample(0.01 + 0.1 + 5 / 30.0);  // plays 5: 3 and 4 never came
  EXPECT_EQ(jb.stats().lost, 2u);
  jb.Push(Frame(4, 4 / 30.0, 4), 0.3);  // too late now
  EXPECT_EQ(jb.stats().late, 1u);
}

TEST(JitterBuffer, HoldsTheNewestThenGivesUp) {
  JitterBufferOptions o;
  o.max_hold_s = 0.3;
  JitterBuffer jb(o);
  jb.Push(Frame(0, 0.0, 7), 0.0);
  auto f = jb.Sample(0.1 + 0.2);
  ASSERT_TRUE(f.has_value());
  EXPECT_EQ(f->expression[0], 7.f);
  EXPECT_FALSE(jb.Sample(0.1 + 0.5).has_value());
}

TEST(InterpolateParams, SlerpsRotationsTheShortWay) {
  FrameParams a = Frame(0, 0, 0), b = Frame(1, 1, 0);
  a.cam_rotation = Eigen::Vector3f(0, 0, 0.2f);
  b.cam_rotation = Eigen::Vector3f(0, 0, 0.6f);
  const FrameParams m = InterpolateParams(a, b, 0.25);
  EXPECT_NEAR(m.cam_rotation.z(), 0.3f, 1e-5);
  EXPECT_NEAR(m.capture_time_s, 0.25, 1e-9);
}

}  // namespace
}  // namespace headcast
