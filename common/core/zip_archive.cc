// Zip archives through libzip.
#include "common/core/zip_archive.h"

#include <zip.h>

#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <vector>

namespace headcast {
namespace {
[[noreturn]] void Fail(const std::string& what, const std::string& why) { throw std::runtime_error(what + ": " + why); }
}  // namespace

std::string ReadFileBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) Fail(path, "cannot open file (does it exist and is it readable?)");
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

void WriteFileAtomically(const std::string& path, const std::string& bytes) {
  const std::string tmp = path + ".tmp";
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) Fail(path, "cannot open for writing");
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    if (!out) Fail(path, "write failed");
  }
  std::filesystem::rename(tmp, path);
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
  ZipEntries entries;
  const zip_int64_t n = zip_get_num_entries(za, 0);
  for (zip_int64_t i = 0; i < n; ++i) {
    zip_stat_t st;
    if (zip_stat_index(za, i, 0, &st) != 0) Fail(path, "cannot stat entry " + std::to_string(i));
    const std::string name = st.name;
    if (!only_entry.empty() && name != only_entry) continue;
    zip_file_t* zf = zip_fopen_index(za, i, 0);
    if (!zf) Fail(path + ":" + name, std::string("cannot open entry: ") + zip_strerror(za));
    std::string bytes(st.size, '\0');
    const zip_int64_t got = zip_fread(zf, bytes.data(), st.size);
    zip_fclose(zf);
    if (got < 0 || static_cast<zip_uint64_t>(got) != st.size) Fail(path + ":" + name, "truncated or corrupt entry");
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
  std::filesystem::rename(tmp, path);
}

}  // namespace headcast
