// The binary range coder and the integer model.
#include "common/codec/range_coder.h"

#include <algorithm>

namespace headcast {
namespace {
constexpr uint32_t kTop = 1u << 24;  // renormalise below this range: one byte out
constexpr int kProbabilityBits = 12;
}  // namespace

void RangeEncoder::Carry() {
  // low overflowed 32 bits: add one to the bytes already out. The coded
  // interval starts inside [0, 1), so the carry stops before the first byte.
  for (size_t i = out_.size(); i-- > 0;) {
    if (static_cast<uint8_t>(out_[i]) != 0xFF) {
      out_[i] = static_cast<char>(static_cast<uint8_t>(out_[i]) + 1);
      return;
    }
    out_[i] = 0;
  }
}

void RangeEncoder::Shift() {
  out_.push_back(static_cast<char>(low_ >> 24));
  low_ = (low_ << 8) & 0xFFFFFFFFu;
  range_ <<= 8;
}

void RangeEncoder::Split(bool bit, uint32_t bound) {
  if (bit) {
    low_ += bound;
    range_ -= bound;
  } else {
    range_ = bound;
  }
  if (low_ > 0xFFFFFFFFu) {
    Carry();
    low_ &= 0xFFFFFFFFu;
  }
  while (range_ < kTop) Shift();
}

void RangeEncoder::Encode(bool bit, BitModel* model) {
  const uint32_t bound = (range_ >> kProbabilityBits) * model->p0;
  model->Update(bit);
  Split(bit, bound);
}

void RangeEncoder::EncodeBypass(bool bit) { Split(bit, range_ >> 1); }

std::string RangeEncoder::Finish() {
  // The value in [low, low + range) with the most trailing zero bytes: the
  // decoder reads zeros past the end, so those bytes need not be sent. A range
  // of at least 2^24 always holds a multiple of 2^24: one byte at most.
  const uint64_t end = low_ + range_;
  uint64_t value = low_;
  for (int zero_bits = 32; zero_bits >= 0; zero_bits -= 8) {
    const uint64_t mask = (uint64_t{1} << zero_bits) - 1;
    const uint64_t v = (low_ + mask) & ~mask;
    if (v < end) {
      value = v;
      break;
    }
  }
  if (value > 0xFFFFFFFFu) {
    Carry();
    value &= 0xFFFFFFFFu;
  }
  for (int shift = 24; shift >= 0; shift -= 8) out_.push_back(static_cast<char>(value >> shift));
  while (!out_.empty() && out_.back() == 0) out_.pop_back();
  std::string out = std::move(out_);
  out_.clear();
  return out;
}

RangeDecoder::RangeDecoder(const uint8_t* data, size_t size) : data_(data), size_(size) {
  for (int i = 0; i < 4; ++i) code_ = (code_ << 8) | (pos_ < size_ ? data_[pos_] : 0), ++pos_;
}

void RangeDecoder::Shift() {
  code_ = (code_ << 8) | (pos_ < size_ ? data_[pos_] : 0);
  ++pos_;
  range_ <<= 8;
}

bool RangeDecoder::Split(uint32_t bound) {
  // Garbage can leave code >= range; the arithmetic stays unsigned and
  // bounded, so it decodes to some symbols, never out of bounds.
  const bool bit = code_ >= bound;
  if (bit) {
    code_ -= bound;
    range_ -= bound;
  } else {
    range_ = bound;
  }
  while (range_ < kTop) Shift();
  return bit;
}

bool RangeDecoder::Decode(BitModel* model) {
  const bool bit = Split((range_ >> kProbabilityBits) * model->p0);
  model->Update(bit);
  return bit;
}

bool RangeDecoder::DecodeBypass() { return Split(range_ >> 1); }

void IntModel::Encode(int64_t v, RangeEncoder* enc) {
  const int context = Context();
  previous_ = v;  // only its sign is used: a clamped v keeps it
  enc->Encode(v != 0, &zero_[context]);
  if (v == 0) return;
  enc->Encode(v < 0, &sign_[context]);
  // The codec keeps |v| far below 2^kMaxBits; longer ones are clamped.
  const uint64_t m = std::min(v < 0 ? uint64_t(0) - static_cast<uint64_t>(v) : static_cast<uint64_t>(v),
                              (uint64_t{1} << kMaxBits) - 1);
  int n = 1;  // bit length of m (>= 1)
  while ((m >> n) != 0) ++n;
  for (int j = 1; j < n; ++j) enc->Encode(true, &length_[std::min(j - 1, kLengthModels - 1)]);
  if (n < kMaxBits) enc->Encode(false, &length_[std::min(n - 1, kLengthModels - 1)]);
  if (n >= 2) enc->Encode((m >> (n - 2)) & 1, &second_bit_[std::min(n - 2, kLengthModels - 1)]);
  for (int b = n - 3; b >= 0; --b) enc->EncodeBypass((m >> b) & 1);
}

int64_t IntModel::Decode(RangeDecoder* dec) {
  const int context = Context();
  if (!dec->Decode(&zero_[context])) return previous_ = 0;
  const bool negative = dec->Decode(&sign_[context]);
  int n = 1;
  while (n < kMaxBits && dec->Decode(&length_[std::min(n - 1, kLengthModels - 1)])) ++n;
  uint64_t m = 1;
  if (n >= 2) m = (m << 1) | (dec->Decode(&second_bit_[std::min(n - 2, kLengthModels - 1)]) ? 1 : 0);
  for (int b = n - 3; b >= 0; --b) m = (m << 1) | (dec->DecodeBypass() ? 1 : 0);
  return previous_ = negative ? -static_cast<int64_t>(m) : static_cast<int64_t>(m);
}

}  // namespace headcast
