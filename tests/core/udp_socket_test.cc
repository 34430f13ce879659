// UDP sockets on loopback: a connected sender and a bound receiver that
// answers to the address a datagram came from; oversized datagrams are
// reported, never truncated; a silent socket times out.
#include "common/core/udp_socket.h"

#include <gtest/gtest.h>

#include <stdexcept>

namespace headcast {
namespace {

TEST(UdpSocket, ABoundSocketReceivesAndAnswersItsPeer) {
  UdpSocket server = UdpSocket::Bind("127.0.0.1", 0);
  ASSERT_GT(server.port(), 0);
  UdpSocket client = UdpSocket::Connect("127.0.0.1", server.port());
  std::string got, peer;
  EXPECT_EQ(server.Receive(&got, 100, 20, &peer), UdpSocket::Received::kTimeout);
  ASSERT_TRUE(client.Send("hello"));
  ASSERT_EQ(server.Receive(&got, 100, 2000, &peer), UdpSocket::Received::kDatagram);
  EXPECT_EQ(got, "hello");
  ASSERT_FALSE(peer.empty());
  ASSERT_TRUE(server.SendTo(peer, "welcome back"));
  ASSERT_EQ(client.Receive(&got, 100, 2000), UdpSocket::Received::kDatagram);
  EXPECT_EQ(got, "welcome back");
  // Larger than the reader allows: consumed and reported, the next one still comes.
  ASSERT_TRUE(client.Send(std::string(101, 'x')));
  ASSERT_TRUE(client.Send(std::string(100, 'y')));
  EXPECT_EQ(server.Receive(&got, 100, 2000), UdpSocket::Received::kTooLarge);
  EXPECT_TRUE(got.empty());
  ASSERT_EQ(server.Receive(&got, 100, 2000), UdpSocket::Received::kDatagram);
  EXPECT_EQ(got, std::string(100, 'y'));
  EXPECT_FALSE(server.SendTo("", "x")) << "no peer";
}

TEST(UdpSocket, APortInUseOrAnUnknownHostIsAClearError) {
  UdpSocket first = UdpSocket::Bind("127.0.0.1", 0);
  try {
    UdpSocket::Bind("127.0.0.1", first.port());
    FAIL() << "bound a port in use";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(std::to_string(first.port())), std::string::npos) << e.what();
  }
  EXPECT_THROW(UdpSocket::Connect("no-such-host.invalid", 9), std::runtime_error);
}

}  // namespace
}  // namespace headcast
