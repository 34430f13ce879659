// Bit streams and varints.
#include "common/codec/bit_stream.h"

namespace headcast {

void BitWriter::Bit(bool b) {
  if (bits_ % 8 == 0) bytes_.push_back(0);
  if (b) bytes_.back() = static_cast<char>(static_cast<uint8_t>(bytes_.back()) | (0x80u >> (bits_ % 8)));
  ++bits_;
}

void BitWriter::Bits(uint64_t value, int count) {
  for (int i = count - 1; i >= 0; --i) Bit((value >> i) & 1u);
}

void BitWriter::ExpGolomb(uint64_t v, int k) {
  const uint64_t x = v + (uint64_t{1} << k);
  int n = 0;
  while ((x >> (n + 1)) != 0) ++n;  // x has n+1 significant bits
  for (int i = 0; i < n - k; ++i) Bit(false);
  Bits(x, n + 1);
}

void BitWriter::SignedExpGolomb(int64_t v, int k) {
  const uint64_t zigzag = v >= 0 ? static_cast<uint64_t>(v) << 1 : (static_cast<uint64_t>(-(v + 1)) << 1) | 1u;
  ExpGolomb(zigzag, k);
}

std::string BitWriter::Finish() { return bytes_; }

bool BitReader::Bit(bool* b) {
  if (!ok_ || pos_ >= size_ * 8) return ok_ = false;
  *b = (data_[pos_ / 8] >> (7 - pos_ % 8)) & 1u;
  ++pos_;
  return true;
}

bool BitReader::Bits(int count, uint64_t* value) {
  uint64_t v = 0;
  for (int i = 0; i < count; ++i) {
    bool b;
    if (!Bit(&b)) return false;
    v = (v << 1) | (b ? 1u : 0u);
  }
  *value = v;
  return true;
}

bool BitReader::ExpGolomb(int k, uint64_t* v) {
  int zeros = 0;
  bool b = false;
  for (;;) {
    if (!Bit(&b)) return false;
    if (b) break;
    if (++zeros > 40) return ok_ = false;  // no parameter needs 2^40: garbage
  }
  uint64_t rest = 0;
  if (!Bits(zeros + k, &rest)) return false;
  const uint64_t x = (uint64_t{1} << (zeros + k)) | rest;
  *v = x - (uint64_t{1} << k);
  return true;
}

bool BitReader::SignedExpGolomb(int k, int64_t* v) {
  uint64_t z;
  if (!ExpGolomb(k, &z)) return false;
  *v = (z & 1u) ? -static_cast<int64_t>(z >> 1) - 1 : static_cast<int64_t>(z >> 1);
  return true;
}

void PutVarint(uint64_t v, std::string* out) {
  while (v >= 0x80) {
    out->push_back(static_cast<char>((v & 0x7f) | 0x80));
    v >>= 7;
  }
  out->push_back(static_cast<char>(v));
}

bool GetVarint(const std::string& in, size_t* pos, uint64_t* v) {
  uint64_t result = 0;
  for (int shift = 0; shift < 64; shift += 7) {
    if (*pos >= in.size()) return false;
    const uint8_t byte = static_cast<uint8_t>(in[(*pos)++]);
    result |= static_cast<uint64_t>(byte & 0x7f) << shift;
    if (!(byte & 0x80)) {
      *v = result;
      return true;
    }
  }
  return false;
}

}  // namespace headcast
