// Datagram sealing with OpenSSL's ChaCha20-Poly1305.
#include "proto/datagram.h"

#include <openssl/evp.h>
#include <openssl/rand.h>

#include <memory>
#include <stdexcept>

namespace headcast {
namespace {

struct CipherContext {
  CipherContext() : ctx(EVP_CIPHER_CTX_new()) {
    if (!ctx) throw std::runtime_error("datagram: cannot make a cipher context");
  }
  ~CipherContext() { EVP_CIPHER_CTX_free(ctx); }
  EVP_CIPHER_CTX* ctx;
};

void PutBigEndian(uint32_t v, uint8_t* out) {
  for (int i = 0; i < 4; ++i) out[i] = static_cast<uint8_t>(v >> (24 - 8 * i));
}

uint32_t GetBigEndian(const uint8_t* in) {
  uint32_t v = 0;
  for (int i = 0; i < 4; ++i) v = (v << 8) | in[i];
  return v;
}

std::array<uint8_t, 12> Nonce(uint32_t connection_id, DatagramDirection direction, uint32_t counter) {
  std::array<uint8_t, 12> nonce{};
  PutBigEndian(connection_id, nonce.data());
  nonce[4] = static_cast<uint8_t>(direction);
  PutBigEndian(counter, nonce.data() + 8);
  return nonce;
}

uint8_t FirstByte(DatagramDirection direction) { return kDatagramVersion | static_cast<uint8_t>(direction); }

}  // namespace

DatagramKey DatagramKey::Random() {
  DatagramKey k;
  uint8_t id[4];
  do {
    if (RAND_bytes(k.key.data(), static_cast<int>(k.key.size())) != 1 || RAND_bytes(id, sizeof(id)) != 1)
      throw std::runtime_error("datagram: the random generator failed");
    k.connection_id = GetBigEndian(id);
  } while (k.connection_id == 0);  // 0 means "no datagrams" in a Welcome
  return k;
}

bool DatagramKey::FromBytes(uint32_t connection_id, const std::string& key, DatagramKey* out, std::string* why) {
  if (key.size() != kDatagramKeyBytes) {
    *why = "datagram key has " + std::to_string(key.size()) + " bytes, not " + std::to_string(kDatagramKeyBytes);
    return false;
  }
  if (connection_id == 0) {
    *why = "datagram connection id 0";
    return false;
  }
  out->connection_id = connection_id;
  std::copy(key.begin(), key.end(), out->key.begin());
  return true;
}

std::string SealDatagram(const DatagramKey& key, DatagramDirection direction, uint32_t counter,
                         const std::string& plaintext) {
  if (plaintext.size() > kMaxDatagramPlaintext)
    throw std::invalid_argument("datagram: " + std::to_string(plaintext.size()) + " bytes do not fit one datagram");
  if (counter == 0) throw std::invalid_argument("datagram: counters start at 1");
  std::string out(kDatagramHeaderBytes + plaintext.size() + kDatagramTagBytes, '\0');
  auto* p = reinterpret_cast<uint8_t*>(out.data());
  p[0] = FirstByte(direction);
  PutBigEndian(key.connection_id, p + 1);
  PutBigEndian(counter, p + 5);
  const auto nonce = Nonce(key.connection_id, direction, counter);
  CipherContext c;
  int len = 0;
  bool ok = EVP_EncryptInit_ex(c.ctx, EVP_chacha20_poly1305(), nullptr, key.key.data(), nonce.data()) == 1 &&
            EVP_EncryptUpdate(c.ctx, nullptr, &len, p, kDatagramHeaderBytes) == 1;
  if (ok && !plaintext.empty())
    ok = EVP_EncryptUpdate(c.ctx, p + kDatagramHeaderBytes, &len, reinterpret_cast<const uint8_t*>(plaintext.data()),
                           static_cast<int>(plaintext.size())) == 1;
  ok = ok && EVP_EncryptFinal_ex(c.ctx, p + kDatagramHeaderBytes + plaintext.size(), &len) == 1 &&
       EVP_CIPHER_CTX_ctrl(c.ctx, EVP_CTRL_AEAD_GET_TAG, kDatagramTagBytes,
                           p + kDatagramHeaderBytes + plaintext.size()) == 1;
  if (!ok) throw std::runtime_error("datagram: sealing failed");
  return out;
}

bool PeekDatagramConnection(const std::string& datagram, DatagramDirection direction, uint32_t* connection_id) {
  if (datagram.size() < kDatagramHeaderBytes + kDatagramTagBytes) return false;
  const auto* p = reinterpret_cast<const uint8_t*>(datagram.data());
  if (p[0] != FirstByte(direction)) return false;
  *connection_id = GetBigEndian(p + 1);
  return true;
}

bool OpenDatagram(const DatagramKey& key, DatagramDirection direction, const std::string& datagram, uint32_t* counter,
                  std::string* plaintext, std::string* why) {
  uint32_t id = 0;
  if (datagram.size() > kMaxDatagramBytes) {
    *why = "datagram of " + std::to_string(datagram.size()) + " bytes, more than " + std::to_string(kMaxDatagramBytes);
    return false;
  }
  if (!PeekDatagramConnection(datagram, direction, &id)) {
    *why = "not a headcast datagram of this direction (too short, another version, the other direction)";
    return false;
  }
  if (id != key.connection_id) {
    *why = "datagram of another connection";
    return false;
  }
  const auto* p = reinterpret_cast<const uint8_t*>(datagram.data());
  const uint32_t n = GetBigEndian(p + 5);
  const size_t body = datagram.size() - kDatagramHeaderBytes - kDatagramTagBytes;
  const auto nonce = Nonce(id, direction, n);
  std::string out(body, '\0');
  std::array<uint8_t, kDatagramTagBytes> tag;
  std::copy(p + kDatagramHeaderBytes + body, p + datagram.size(), tag.begin());
  CipherContext c;
  int len = 0;
  bool ok = EVP_DecryptInit_ex(c.ctx, EVP_chacha20_poly1305(), nullptr, key.key.data(), nonce.data()) == 1 &&
            EVP_DecryptUpdate(c.ctx, nullptr, &len, p, kDatagramHeaderBytes) == 1;
  if (ok && body > 0)
    ok = EVP_DecryptUpdate(c.ctx, reinterpret_cast<uint8_t*>(out.data()), &len, p + kDatagramHeaderBytes,
                           static_cast<int>(body)) == 1;
  ok = ok && EVP_CIPHER_CTX_ctrl(c.ctx, EVP_CTRL_AEAD_SET_TAG, kDatagramTagBytes, tag.data()) == 1 &&
       EVP_DecryptFinal_ex(c.ctx, reinterpret_cast<uint8_t*>(out.data()) + body, &len) == 1;
  if (!ok || n == 0) {
    *why = "datagram does not authenticate";
    return false;
  }
  *counter = n;
  *plaintext = std::move(out);
  return true;
}

DatagramOrder::Verdict DatagramOrder::Take(uint32_t counter, uint64_t* missing) {
  if (counter <= last_) return Verdict::kStale;
  const uint64_t gap = counter - last_ - 1;
  last_ = counter;
  if (missing) *missing = gap;
  return gap == 0 ? Verdict::kNext : Verdict::kAfterGap;
}

}  // namespace headcast
