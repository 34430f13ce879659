// Zip archives as name -> bytes maps (npz files, avatar files), through libzip.
#pragma once

#include <map>
#include <string>

namespace headcast {

using ZipEntries = std::map<std::string, std::string>;

// Throws std::runtime_error naming the file (and entry) if it is missing,
// not a zip, truncated or corrupt.
ZipEntries ReadZip(const std::string& path);

// Written to "<path>.tmp" and renamed, so readers never see half a file.
// `compress`: deflate at level 1 (most of the gain, little of the time).
void WriteZip(const std::string& path, const ZipEntries& entries, bool compress = true);

// Writes bytes to a file the same atomic way.
void WriteFileAtomically(const std::string& path, const std::string& bytes);
std::string ReadFileBytes(const std::string& path);

}  // namespace headcast
