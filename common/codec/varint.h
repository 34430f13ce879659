// Unsigned LEB128 varints: packet headers and the length prefixes of a batch.
#pragma once

#include <cstdint>
#include <string>

namespace headcast {

void PutVarint(uint64_t v, std::string* out);
// Reads at *pos; false on truncation or an over-long encoding.
bool GetVarint(const std::string& in, size_t* pos, uint64_t* v);

}  // namespace headcast
