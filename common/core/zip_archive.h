// Zip archives as name -> bytes maps (npz files, avatar files), through libzip.
#pragma once

#include <map>
#include <nlohmann/json.hpp>
#include <string>

namespace headcast {

using ZipEntries = std::map<std::string, std::string>;

// Throws std::runtime_error naming the file (and entry) if it is missing,
// not a zip, truncated or corrupt. With `only_entry`, just that entry is read
// (absent from the result when the archive has none of that name).
ZipEntries ReadZip(const std::string& path, const std::string& only_entry = {});

// The JSON document stored as `entry` (an avatar's manifest.json, say);
// throws naming the file when it is missing or not JSON.
nlohmann::json ReadZipJson(const std::string& path, const std::string& entry);

// Written to "<path>.tmp", flushed to the disk and renamed, so readers never
// see half a file and a crash or power cut leaves the old file or the new one.
// `compress`: deflate at level 1 (most of the gain, little of the time).
void WriteZip(const std::string& path, const ZipEntries& entries, bool compress = true);

// Writes bytes to a file the same atomic, durable way; a full disk is an error.
void WriteFileAtomically(const std::string& path, const std::string& bytes);

// fsync of a file or a folder (after a rename in it); throws naming the path.
void SyncToDisk(const std::string& path);
std::string ReadFileBytes(const std::string& path);

}  // namespace headcast
