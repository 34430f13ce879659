// A binary adaptive range coder and the integer models the parameter codec
// builds on it. Why not Exp-Golomb codes: a real face's tracked parameters
// hold dozens of components that barely move, and a prefix code spends at
// least one bit on each of them every frame; an adaptive binary model spends a
// small fraction of a bit on a value that is almost always the same.
//
// The coder keeps 32 bits of state; a packet ends with at most one byte beyond
// what the symbols settled, and trailing zero bytes are dropped (the decoder
// reads zeros past the end), so a short packet carries no fixed flush cost.
#pragma once

#include <array>
#include <cstdint>
#include <string>

namespace headcast {

// The probability that a binary symbol is 0, in 1/4096, adapting towards what
// it sees: after each symbol it moves 1/16 of the way (fast enough to follow a
// face's changes in a few frames at 30 fps).
struct BitModel {
  uint16_t p0 = 2048;
  void Update(bool bit) {
    if (bit)
      p0 -= p0 >> 4;
    else
      p0 += (4096 - p0) >> 4;
  }
};

class RangeEncoder {
 public:
  void Encode(bool bit, BitModel* model);
  void EncodeBypass(bool bit);  // probability 1/2, no model
  // The bytes so far, terminated: ends the packet (the encoder is spent).
  std::string Finish();

 private:
  void Split(bool bit, uint32_t bound);  // the symbol's part of the range, then renormalise
  void Shift();
  void Carry();
  std::string out_;
  uint64_t low_ = 0;
  uint32_t range_ = 0xFFFFFFFFu;
};

class RangeDecoder {
 public:
  RangeDecoder(const uint8_t* data, size_t size);
  bool Decode(BitModel* model);
  bool DecodeBypass();
  // Bytes the decoder has taken in (those past the end read as zero). A
  // packet longer than this has trailing bytes no symbol accounts for.
  size_t consumed() const { return pos_; }

 private:
  bool Split(uint32_t bound);
  void Shift();
  const uint8_t* data_;
  size_t size_;
  size_t pos_ = 0;
  uint32_t code_ = 0;
  uint32_t range_ = 0xFFFFFFFFu;
};

// A signed integer under adaptive models: is it zero, its sign, the length of
// its magnitude (unary, one model per length), the magnitude's first bit below
// its leading one (a model per length: small magnitudes are likelier), then
// its lower bits at probability 1/2. Most residuals are 0 or small, and each
// value's own models learn how small. Whether it is zero and its sign are
// modelled apart for each sign of the previous integer coded with the model:
// a face's motion carries on from frame to frame.
class IntModel {
 public:
  // The longest magnitude, far beyond any value the codec allows: garbage
  // decodes to at most this many bits, and an encoder clamps to it.
  static constexpr int kMaxBits = 42;
  void Encode(int64_t v, RangeEncoder* enc);
  int64_t Decode(RangeDecoder* dec);

 private:
  static constexpr int kLengthModels = 12;  // longer lengths share the last model
  int Context() const { return previous_ < 0 ? 0 : previous_ == 0 ? 1 : 2; }
  std::array<BitModel, 3> zero_, sign_;
  std::array<BitModel, kLengthModels> length_, second_bit_;
  int64_t previous_ = 0;
};

}  // namespace headcast
