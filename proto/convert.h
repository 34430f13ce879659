// The one place that converts between headcast's types and its proto messages.
#pragma once

#include "common/codec/param_codec.h"
#include "common/headmodel/params.h"
#include "proto/headcast.pb.h"

namespace headcast {

void ToProto(const FrameParams& in, v1::FrameParams* out);
// Fails (false, `why`) on wrong vector lengths; values are checked by FrameParams::IsValid.
bool FromProto(const v1::FrameParams& in, FrameParams* out, std::string* why = nullptr);

void ToProto(const SubjectParams& in, v1::SubjectParams* out);
bool FromProto(const v1::SubjectParams& in, SubjectParams* out, std::string* why = nullptr);

void ToProto(const CodecLayout& in, double fps, v1::ParameterLayout* out);
// Checks the layout (CodecLayout::Check) and says what is wrong.
bool FromProto(const v1::ParameterLayout& in, CodecLayout* out, std::string* why = nullptr);

}  // namespace headcast
