// Zip archives through libzip.
#include "common/core/zip_archive.h"

#include <fcntl.h>
#include <unistd.h>
#include <zip.h>
#include <zlib.h>

#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <vector>

namespace headcast {
namespace {
[[noreturn]] void Fail(const std::string& what, const std::string& why) { throw std::runtime_error(what + ": " + why); }

// What an archive of `file_bytes` may unpack to: deflate packs real arrays
// and weights a few times at most, so anything claiming far more is a
// forgery or a zip bomb, refused before a byte is allocated for it.
uint64_t UnpackLimit(uint64_t file_bytes) {
  constexpr uint64_t kFloor = uint64_t(64) << 20, kCeiling = uint64_t(16) << 30, kMaxRatio = 100;
  return std::min(kCeiling, std::max(kFloor, kMaxRatio * file_bytes));
}

uint32_t Crc32(const std::string& bytes) {
  uLong crc = crc32(0L, Z_NULL, 0);
  for (size_t at = 0; at < bytes.size();) {  // zlib takes at most 4 GiB a call
    const uInt n = static_cast<uInt>(std::min<size_t>(bytes.size() - at, 1u << 30));
    crc = crc32(crc, reinterpret_cast<const Bytef*>(bytes.data() + at), n);
    at += n;
  }
  return static_cast<uint32_t>(crc);
}
}  // namespace

std::string ReadFileBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) Fail(path, "cannot open file (does it exist and is it readable?)");
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

void SyncToDisk(const std::string& path) {
  const int fd = open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) Fail(path, std::string("cannot open to sync: ") + std::strerror(errno));
  const int rc = fsync(fd);
  const int fsync_errno = errno;
  close(fd);
  if (rc != 0) Fail(path, std::string("sync to disk failed: ") + std::strerror(fsync_errno));
}

namespace {
// The rename is atomic; the syncs make it durable: the data before it, the folder after.
void CommitTemporary(const std::string& tmp, const std::string& path) {
  SyncToDisk(tmp);
  std::filesystem::rename(tmp, path);
  const std::filesystem::path parent = std::filesystem::path(path).parent_path();
  SyncToDisk(parent.empty() ? "." : parent.string());
}
}  // namespace

void WriteFileAtomically(const std::string& path, const std::string& bytes) {
  const std::string tmp = path + ".tmp";
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) Fail(path, "cannot open for writing");
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    out.close();  // a full disk often shows only here
    if (!out) Fail(path, "write failed (disk full?)");
  }
  CommitTemporary(tmp, path);
}

ZipEntries ReadZip(const std::string& path, const std::string& only_entry) {
  if (!std::filesystem::exists(path)) Fail(path, "no such file");
  int error = 0;
  zip_t* za = zip_open(path.c_str(), ZIP_RDONLY | ZIP_CHECKCONS, &error);
  if (!za) {
    zip_error_t ze;
    zip_error_init_with_code(&ze, error);
    std::string why = zip_error_strerror(&ze);
    zip_error_fini(&ze);
    Fail(path, "not a readable zip archive (" + why + "; truncated or another kind of file?)");
  }
  std::unique_ptr<zip_t, int (*)(zip_t*)> closer(za, zip_close);
  const uint64_t file_bytes = std::filesystem::file_size(path);
  const uint64_t limit = UnpackLimit(file_bytes);
  uint64_t unpacked = 0;
  ZipEntries entries;
  const zip_int64_t n = zip_get_num_entries(za, 0);
  for (zip_int64_t i = 0; i < n; ++i) {
    zip_stat_t st;
    if (zip_stat_index(za, i, 0, &st) != 0) Fail(path, "cannot stat entry " + std::to_string(i));
    constexpr zip_uint64_t kNeeded = ZIP_STAT_NAME | ZIP_STAT_SIZE | ZIP_STAT_COMP_SIZE | ZIP_STAT_CRC;
    if ((st.valid & kNeeded) != kNeeded) Fail(path, "entry " + std::to_string(i) + " lacks its name, sizes or CRC");
    const std::string name = st.name;
    if (!only_entry.empty() && name != only_entry) continue;
    if (st.comp_size > file_bytes)
      Fail(path + ":" + name, "entry claims " + std::to_string(st.comp_size) + " packed bytes; the file has " +
                                  std::to_string(file_bytes) + " (truncated or corrupt)");
    if (st.size > limit - unpacked)
      Fail(path + ":" + name, "entry claims " + std::to_string(st.size) + " bytes, more than a " +
                                  std::to_string(file_bytes) + "-byte archive may unpack to (corrupt, or a zip bomb)");
    unpacked += st.size;
    zip_file_t* zf = zip_fopen_index(za, i, 0);
    if (!zf) Fail(path + ":" + name, std::string("cannot open entry: ") + zip_strerror(za));
    std::string bytes(st.size, '\0');
    const zip_int64_t got = zip_fread(zf, bytes.data(), st.size);
    zip_fclose(zf);
    if (got < 0 || static_cast<zip_uint64_t>(got) != st.size) Fail(path + ":" + name, "truncated or corrupt entry");
    // libzip checks the CRC only when a read reaches the entry's end, which
    // reading exactly its size does not; one flipped bit must not load.
    if (Crc32(bytes) != st.crc) Fail(path + ":" + name, "CRC mismatch: the entry is corrupt");
    entries[name] = std::move(bytes);
  }
  return entries;
}

nlohmann::json ReadZipJson(const std::string& path, const std::string& entry) {
  const ZipEntries entries = ReadZip(path, entry);
  const auto it = entries.find(entry);
  if (it == entries.end()) Fail(path, "no " + entry);
  try {
    return nlohmann::json::parse(it->second);
  } catch (const std::exception& e) {
    Fail(path, entry + " is not valid JSON: " + e.what());
  }
}

void WriteZip(const std::string& path, const ZipEntries& entries, bool compress) {
  const std::string tmp = path + ".tmp";
  std::filesystem::remove(tmp);
  int error = 0;
  zip_t* za = zip_open(tmp.c_str(), ZIP_CREATE | ZIP_TRUNCATE, &error);
  if (!za) Fail(path, "cannot create archive (is the folder writable?)");
  for (const auto& [name, bytes] : entries) {
    // The entries map outlives zip_close, so libzip may read the buffers late.
    zip_source_t* src = zip_source_buffer(za, bytes.data(), bytes.size(), 0);
    const zip_int64_t idx = src ? zip_file_add(za, name.c_str(), src, ZIP_FL_OVERWRITE) : -1;
    if (idx < 0) {
      if (src) zip_source_free(src);
      zip_discard(za);
      Fail(path, "cannot add " + name);
    }
    zip_set_file_compression(za, idx, compress ? ZIP_CM_DEFLATE : ZIP_CM_STORE, compress ? 1 : 0);
  }
  if (zip_close(za) != 0) {
    const std::string why = zip_strerror(za);
    zip_discard(za);
    Fail(path, "writing failed: " + why);
  }
  CommitTemporary(tmp, path);
}

}  // namespace headcast
