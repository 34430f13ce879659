// Bit-level writing/reading with Exp-Golomb codes, for the parameter codec.
#pragma once

#include <cstdint>
#include <string>

namespace headcast {

class BitWriter {
 public:
  void Bit(bool b);
  void Bits(uint64_t value, int count);  // most significant first
  // Exp-Golomb of order k for v >= 0: small values in few bits.
  void ExpGolomb(uint64_t v, int k);
  void SignedExpGolomb(int64_t v, int k);  // zigzag, then ExpGolomb
  // The bytes so far; the last byte is zero-padded.
  std::string Finish();
  size_t bit_count() const { return bits_; }

 private:
  std::string bytes_;
  size_t bits_ = 0;
};

class BitReader {
 public:
  BitReader(const uint8_t* data, size_t size) : data_(data), size_(size) {}
  // Each returns false (and leaves ok() false) when the data runs out or a
  // code is longer than any valid one: garbage never reads past the end.
  bool Bit(bool* b);
  bool Bits(int count, uint64_t* value);
  bool ExpGolomb(int k, uint64_t* v);
  bool SignedExpGolomb(int k, int64_t* v);
  bool ok() const { return ok_; }
  size_t bits_read() const { return pos_; }

 private:
  const uint8_t* data_;
  size_t size_;
  size_t pos_ = 0;
  bool ok_ = true;
};

// Unsigned LEB128 varints (packet headers, length prefixes).
void PutVarint(uint64_t v, std::string* out);
// Reads at *pos; false on truncation or an over-long encoding.
bool GetVarint(const std::string& in, size_t* pos, uint64_t* v);

}  // namespace headcast
