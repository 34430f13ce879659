// The parameter codec: per-component quantisation (steps from each component's
// measured effect on the mesh), prediction from the previous frame, the
// residuals under adaptive binary models with a range coder (one set of models
// per value, learnt from the frames since the last key frame), periodic key
// frames. Wire-independent.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "common/codec/range_coder.h"
#include "common/headmodel/head_model.h"
#include "common/headmodel/head_outline.h"
#include "common/headmodel/params.h"

namespace headcast {

constexpr int kCodecVersion = 2;
constexpr size_t kMaxFingerprintBytes = 128;

// What both ends agree on when a session starts (sent in Hello).
// The outline's quantisation step, mm: a fifth of a pixel or less on a 256² avatar at arm's length.
inline constexpr float kOutlineStepMm = 0.25f;

struct CodecLayout {
  int num_expression = 0;                  // E of the head model; unsent components decode as 0
  std::vector<int> expression_components;  // indices sent, ascending, each < num_expression
  // Quantisation step per coded value, in order: the sent expression
  // components, jaw, neck, left eye, right eye (3 each, radians), cam rotation
  // (3, radians), cam translation (3, metres), then with skin_colour the skin's
  // R, G, B (0..1; a frame without one travels as 0, 0, 0), then the
  // outline's outline_bins values (mm; a frame without one travels as zeros).
  std::vector<float> steps;
  bool skin_colour = false;     // FrameParams::skin_colour travels (a peer that predates it sends none)
  int outline_bins = 0;         // FrameParams::outline travels in this many values (0: none; a peer that predates it)
  int key_frame_interval = 30;  // a key frame at least this often, frames
  // HeadModel::fingerprint() of the model the parameters belong to: a receiver
  // refuses to drive an avatar of another model with them.
  std::string head_model_fingerprint;

  int num_values() const {
    return static_cast<int>(expression_components.size()) + 18 + (skin_colour ? 3 : 0) + outline_bins;
  }
  void Check() const;  // throws std::invalid_argument naming the problem

  // Steps such that one step of any component moves no vertex of `model` by
  // more than `max_vertex_error_m` (rotations: about the joint, over the mesh's
  // extent). `components` empty = every expression component.
  // The skin colour travels in steps of one 8-bit level, the outline in
  // kOutlineStepMm.
  static CodecLayout FromModel(const HeadModel& model, double max_vertex_error_m = 2e-4,
                               std::vector<int> components = {}, int key_frame_interval = 30, bool skin_colour = true,
                               int outline_bins = OutlineOptions{}.bins);
};

// What encoder and decoder keep in step between packets: the last frame's
// quantised values and header, and the adaptive models (reset by a key frame,
// so a decoder can start there).
struct CodecState {
  explicit CodecState(int num_values);
  void Reset();  // as after a key frame's header: fresh models
  std::vector<int64_t> previous;
  std::vector<IntModel> value_models;
  IntModel key_values, sequence_step, time_step, confidence;
  uint64_t coded = 0, previous_sequence = 0;
  int64_t previous_time_ms = 0, sequence_delta = 0, time_delta_ms = 0, confidence_level = 0;
};

class ParamEncoder {
 public:
  explicit ParamEncoder(CodecLayout layout);
  // One frame to one packet. `time_origin_s` is subtracted from capture times
  // (the session start), which travel in whole milliseconds.
  std::string Encode(const FrameParams& frame, double time_origin_s = 0);
  void ForceKeyFrame() { force_key_ = true; }
  const CodecLayout& layout() const { return layout_; }

 private:
  CodecLayout layout_;
  CodecState state_;
  int since_key_ = 0;
  bool force_key_ = true;
};

class ParamDecoder {
 public:
  explicit ParamDecoder(CodecLayout layout);
  // Decodes one packet. Returns false with `why` for garbage, a truncated or
  // foreign packet, values out of range, or a delta frame whose reference is
  // missing (it then waits for the next key frame). Never reads out of bounds.
  // An entropy-coded packet has no redundancy to catch every flipped bit:
  // what decodes is kept within each value's range.
  bool Decode(const std::string& packet, FrameParams* out, std::string* why, double time_origin_s = 0);
  const CodecLayout& layout() const { return layout_; }
  bool waiting_for_key_frame() const { return !have_reference_; }
  // Packets were lost since the last one decoded (a datagram gap): the next
  // delta frames would decode against the wrong reference, so wait for a key frame.
  void AwaitKeyFrame() { have_reference_ = false; }

 private:
  CodecLayout layout_;
  CodecState state_;
  bool have_reference_ = false;
};

// Several packets in one message: varint length + bytes each.
std::string PackPackets(const std::vector<std::string>& packets);

// The most packets one message may carry (the sender's max_batch is at most this).
constexpr int kMaxPacketsPerMessage = 1000;

// Splits a message's payload. Refuses, saying why: a truncated or corrupt
// length, an empty packet (no coded frame is empty), more than `max_packets`
// packets — before anything is stored for them, so a message of tiny packets
// cannot multiply into memory.
bool UnpackPackets(const std::string& payload, std::vector<std::string>* packets, std::string* why,
                   int max_packets = kMaxPacketsPerMessage);

}  // namespace headcast
