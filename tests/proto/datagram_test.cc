// Sealed datagrams: what one end seals the other opens, and nothing else is
// taken — a changed bit, another key, connection or direction, a short,
// oversized or replayed datagram.
#include "proto/datagram.h"

#include <gtest/gtest.h>

#include <stdexcept>

namespace headcast {
namespace {

TEST(Datagram, WhatIsSealedOpensWithItsCounter) {
  const DatagramKey key = DatagramKey::Random();
  const std::string text = "one coded batch of frames";
  const std::string d = SealDatagram(key, DatagramDirection::kUplink, 7, text);
  EXPECT_EQ(d.size(), kDatagramHeaderBytes + text.size() + kDatagramTagBytes);
  EXPECT_EQ(d.find(text), std::string::npos) << "the payload travels encrypted";
  uint32_t id = 0, counter = 0;
  ASSERT_TRUE(PeekDatagramConnection(d, DatagramDirection::kUplink, &id));
  EXPECT_EQ(id, key.connection_id);
  std::string plain, why;
  ASSERT_TRUE(OpenDatagram(key, DatagramDirection::kUplink, d, &counter, &plain, &why)) << why;
  EXPECT_EQ(plain, text);
  EXPECT_EQ(counter, 7u);
  // An empty message seals and opens too (the tag alone).
  ASSERT_TRUE(OpenDatagram(key, DatagramDirection::kDownlink, SealDatagram(key, DatagramDirection::kDownlink, 1, ""),
                           &counter, &plain, &why));
  EXPECT_TRUE(plain.empty());
}

TEST(Datagram, AnyChangedBitAnotherKeyOrTheOtherDirectionIsRefused) {
  const DatagramKey key = DatagramKey::Random();
  const std::string d = SealDatagram(key, DatagramDirection::kUplink, 3, "frames");
  uint32_t counter = 0;
  std::string plain, why;
  for (size_t i = 0; i < d.size(); ++i)
    for (int bit = 0; bit < 8; bit += 3) {
      std::string bad = d;
      bad[i] = static_cast<char>(bad[i] ^ (1 << bit));
      EXPECT_FALSE(OpenDatagram(key, DatagramDirection::kUplink, bad, &counter, &plain, &why))
          << "byte " << i << " bit " << bit;
    }
  DatagramKey other = DatagramKey::Random();
  other.connection_id = key.connection_id;  // the same header, another key
  EXPECT_FALSE(OpenDatagram(other, DatagramDirection::kUplink, d, &counter, &plain, &why));
  EXPECT_EQ(why, "datagram does not authenticate");
  // Reflected back at its sender, an uplink datagram is not a downlink one.
  EXPECT_FALSE(OpenDatagram(key, DatagramDirection::kDownlink, d, &counter, &plain, &why));
  EXPECT_NE(why.find("direction"), std::string::npos) << why;
  // Short, empty, oversized.
  EXPECT_FALSE(OpenDatagram(key, DatagramDirection::kUplink, d.substr(0, 20), &counter, &plain, &why));
  EXPECT_FALSE(OpenDatagram(key, DatagramDirection::kUplink, "", &counter, &plain, &why));
  EXPECT_FALSE(
      OpenDatagram(key, DatagramDirection::kUplink, d + std::string(kMaxDatagramBytes, 'x'), &counter, &plain, &why));
  EXPECT_NE(why.find("more than"), std::string::npos) << why;
}

TEST(Datagram, SealingRefusesWhatCannotTravel) {
  const DatagramKey key = DatagramKey::Random();
  EXPECT_THROW(SealDatagram(key, DatagramDirection::kUplink, 1, std::string(kMaxDatagramPlaintext + 1, 'x')),
               std::invalid_argument);
  EXPECT_NO_THROW(SealDatagram(key, DatagramDirection::kUplink, 1, std::string(kMaxDatagramPlaintext, 'x')));
  EXPECT_THROW(SealDatagram(key, DatagramDirection::kUplink, 0, "x"), std::invalid_argument);
  DatagramKey k;
  std::string why;
  EXPECT_FALSE(DatagramKey::FromBytes(5, std::string(31, 'k'), &k, &why));
  EXPECT_NE(why.find("31 bytes"), std::string::npos) << why;
  EXPECT_FALSE(DatagramKey::FromBytes(0, std::string(32, 'k'), &k, &why));
  ASSERT_TRUE(DatagramKey::FromBytes(5, key.key_bytes(), &k, &why)) << why;
  EXPECT_EQ(k.key, key.key);
  // Keys are fresh each time.
  EXPECT_NE(DatagramKey::Random().key, DatagramKey::Random().key);
}

TEST(DatagramOrder, OnlyNewerCountersAreTakenAndGapsAreCounted) {
  DatagramOrder order;
  uint64_t missing = 99;
  EXPECT_EQ(order.Take(1, &missing), DatagramOrder::Verdict::kNext);
  EXPECT_EQ(missing, 0u);
  EXPECT_EQ(order.Take(2), DatagramOrder::Verdict::kNext);
  EXPECT_EQ(order.Take(2), DatagramOrder::Verdict::kStale) << "a replay";
  EXPECT_EQ(order.Take(1), DatagramOrder::Verdict::kStale);
  EXPECT_EQ(order.Take(5, &missing), DatagramOrder::Verdict::kAfterGap);
  EXPECT_EQ(missing, 2u);
  EXPECT_EQ(order.Take(4), DatagramOrder::Verdict::kStale) << "overtaken: useless to a delta decoder";
  EXPECT_EQ(order.last(), 5u);
}

}  // namespace
}  // namespace headcast
