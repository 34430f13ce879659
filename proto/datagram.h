// A session's datagrams: the sealed format both ends share (header, AEAD,
// the order rule), free of sockets. A datagram is
//   version and direction (1 B) | connection id (4 B, big-endian)
//   | counter (4 B, big-endian) | ChaCha20-Poly1305 ciphertext | tag (16 B)
// with the 9-byte header as associated data and the nonce made of the
// connection id, the direction and the counter (unique: a key lives one
// session, each direction's counter only grows). Uplink datagrams carry one
// serialised v1::Frames, downlink ones one v1::Downlink (Stats, KeyFrameRequest):
// on a narrow link a message on the stream would cost the uplink its ACKs.
#pragma once

#include <array>
#include <cstdint>
#include <string>

namespace headcast {

constexpr uint8_t kDatagramVersion = 1;
enum class DatagramDirection : uint8_t { kUplink = 0, kDownlink = 0x80 };  // the high bit of the first byte
constexpr size_t kDatagramHeaderBytes = 9;
constexpr size_t kDatagramTagBytes = 16;
constexpr size_t kDatagramKeyBytes = 32;
// The largest datagram either end makes or takes: under any path's MTU
// (IPv6's minimum is 1280), so no datagram is ever fragmented.
constexpr size_t kMaxDatagramBytes = 1200;
constexpr size_t kMaxDatagramPlaintext = kMaxDatagramBytes - kDatagramHeaderBytes - kDatagramTagBytes;

struct DatagramKey {
  uint32_t connection_id = 0;
  std::array<uint8_t, kDatagramKeyBytes> key{};
  // A fresh random key and connection id (the OS's CSPRNG through OpenSSL).
  static DatagramKey Random();
  // From a Welcome's offer; false with *why for a key of the wrong length.
  static bool FromBytes(uint32_t connection_id, const std::string& key, DatagramKey* out, std::string* why);
  std::string key_bytes() const { return std::string(key.begin(), key.end()); }
};

// Seals `plaintext` (at most kMaxDatagramPlaintext bytes: throws
// std::invalid_argument otherwise) as datagram number `counter` (>= 1) of `direction`.
std::string SealDatagram(const DatagramKey& key, DatagramDirection direction, uint32_t counter,
                         const std::string& plaintext);

// The connection id of a datagram's header, to find its session's key;
// false for anything too short or of another version or direction.
bool PeekDatagramConnection(const std::string& datagram, DatagramDirection direction, uint32_t* connection_id);

// Opens a datagram of `direction` sealed under `key`: false with *why for a
// short, foreign, oversized or forged datagram (any changed bit fails the
// tag), or one of the other direction (a reflected datagram).
bool OpenDatagram(const DatagramKey& key, DatagramDirection direction, const std::string& datagram, uint32_t* counter,
                  std::string* plaintext, std::string* why);

// The receiver's order rule: a counter is taken only if it is above every
// counter taken before (a repeat is a replay; a datagram overtaken by a later
// one is useless to a decoder that codes each frame against the previous).
class DatagramOrder {
 public:
  enum class Verdict { kNext, kAfterGap, kStale };
  // kAfterGap: `counter` is new but datagrams before it are missing
  // (*missing says how many); kStale: refused.
  Verdict Take(uint32_t counter, uint64_t* missing = nullptr);
  uint32_t last() const { return last_; }

 private:
  uint32_t last_ = 0;
};

}  // namespace headcast
