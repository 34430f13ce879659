// TLS sessions on 127.0.0.1: server certificate, optional client certificates,
// and refusals for a wrong CA or a missing client certificate.
#include <gtest/gtest.h>

#include <algorithm>
#include <cctype>
#include <cstdlib>

#include "common/headmodel/builtin_head.h"
#include "common/headmodel/synthetic_motion.h"
#include "proto/protocol.h"
#include "receiver/session_server.h"
#include "sender/session_client.h"
#include "tests/testing/test_data.h"

namespace headcast {
namespace {

class TlsTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new std::string(testing::TempDir("certs"));
    const char* source = std::getenv("HEADCAST_SOURCE_DIR");  // set by ctest; else run from the checkout
    const std::string script = std::string(source ? source : ".") + "/deploy/make_certs.sh";
    ASSERT_EQ(
        std::system((script + " " + *dir_ + "/a > /dev/null && " + script + " " + *dir_ + "/b > /dev/null").c_str()),
        0);
  }
  static std::string P(const std::string& name) { return *dir_ + "/" + name; }
  void Serve(bool require_client_cert) {
    static const HeadModel model = MakeBuiltinHead();
    layout_ = CodecLayout::FromModel(model);
    ReceiverServerOptions o;
    o.listen = "127.0.0.1:0";
    o.tokens = {"t"};
    o.tls_cert = P("a/server.pem");
    o.tls_key = P("a/server.key");
    if (require_client_cert) o.tls_client_ca = P("a/ca.pem");
    server_ = std::make_unique<ReceiverServer>(
        o, std::map<std::string, AvatarEntry>{{"demo", {model.fingerprint(), model.num_expression()}}});
    server_->Start();
  }
  SenderOptions Client(const std::string& ca_set, bool client_cert) {
    SenderOptions s;
    s.target = "127.0.0.1:" + std::to_string(server_->port());
    s.token = "t";
    s.avatar_id = "demo";
    s.tls_ca = P(ca_set + "/ca.pem");
    if (client_cert) {
      s.tls_client_cert = P(ca_set + "/client.pem");
      s.tls_client_key = P(ca_set + "/client.key");
    }
    s.welcome_timeout_s = 2;
    return s;
  }
  static std::string* dir_;
  std::unique_ptr<ReceiverServer> server_;
  CodecLayout layout_;
};
std::string* TlsTest::dir_ = nullptr;

TEST_F(TlsTest, ServerCertificate) {
  Serve(false);
  SenderClient good(Client("a", false), layout_);
  good.Start();
  EXPECT_TRUE(good.WaitStreaming(5)) << good.counters().last_error;
  good.Stop();
  SenderClient wrong_ca(Client("b", false), layout_);  // trusts another CA
  wrong_ca.Start();
  EXPECT_FALSE(wrong_ca.WaitStreaming(2));
  wrong_ca.Stop();
  EXPECT_EQ(wrong_ca.counters().connects, 0u);
  // The transport's reason, not just "cannot reach the receiver".
  std::string error = wrong_ca.counters().last_error;
  std::transform(error.begin(), error.end(), error.begin(), [](unsigned char c) { return std::tolower(c); });
  EXPECT_TRUE(error.find("ssl") != std::string::npos || error.find("certificate") != std::string::npos ||
              error.find("handshake") != std::string::npos)
      << wrong_ca.counters().last_error;
}

TEST_F(TlsTest, ClientCertificatesWhenRequired) {
  Serve(true);
  SenderClient with_cert(Client("a", true), layout_);
  with_cert.Start();
  EXPECT_TRUE(with_cert.WaitStreaming(5)) << with_cert.counters().last_error;
  with_cert.Stop();
  SenderClient without(Client("a", false), layout_);
  without.Start();
  EXPECT_FALSE(without.WaitStreaming(2));
  without.Stop();
  EXPECT_EQ(without.counters().connects, 0u);
  SenderOptions foreign = Client("a", false);  // a certificate from another CA
  foreign.tls_client_cert = P("b/client.pem");
  foreign.tls_client_key = P("b/client.key");
  SenderClient other(foreign, layout_);
  other.Start();
  EXPECT_FALSE(other.WaitStreaming(2));
  other.Stop();
}

}  // namespace
}  // namespace headcast
