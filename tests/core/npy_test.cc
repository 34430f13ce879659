// npy/npz reading and writing: every dtype round-trips; bad files are refused by name.
#include "common/core/npy.h"

#include <gtest/gtest.h>
#include <sys/resource.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>

#include "common/core/zip_archive.h"
#include "tests/testing/test_data.h"

namespace headcast {
namespace {

template <typename T>
void ExpectRoundTrip(const std::vector<T>& values, std::vector<int64_t> shape) {
  const NpyArray a = NpyArray::From<T>(shape, values.data());
  const NpyArray b = ParseNpy(SerializeNpy(a), "memory");
  ASSERT_EQ(b.dtype(), a.dtype());
  ASSERT_EQ(b.shape(), shape);
  for (size_t i = 0; i < values.size(); ++i) EXPECT_EQ(b.data<T>()[i], values[i]);
}

TEST(Npy, EveryDtypeRoundTrips) {
  ExpectRoundTrip<float>({1.5f, -2.f, 3.25f, 0.f, 1e-7f, 8.f}, {2, 3});
  ExpectRoundTrip<double>({1.5, -2, 3.25}, {3});
  ExpectRoundTrip<int32_t>({-1, 7, 1 << 30, 0}, {2, 2});
  ExpectRoundTrip<int64_t>({-1, int64_t(1) << 40}, {2, 1});
  ExpectRoundTrip<uint8_t>({0, 255, 17}, {3});
  const bool flags[4] = {true, false, true, true};
  const NpyArray b = ParseNpy(SerializeNpy(NpyArray::From<bool>({4}, flags)), "memory");
  ASSERT_EQ(b.dtype(), DType::kBool);
  for (int i = 0; i < 4; ++i) EXPECT_EQ(b.data<bool>()[i], flags[i]);
  ExpectRoundTrip<float>({}, {0, 3});
  ExpectRoundTrip<float>({}, {24591, 3, 0});  // empty, though its leading dimensions outgrow the bytes present
}

TEST(Npy, ConvertsBetweenNumericTypes) {
  const std::vector<int32_t> v = {1, -2, 3};
  const NpyArray a = NpyArray::From<int32_t>({3}, v.data());
  EXPECT_EQ(a.ToDoubles(), (std::vector<double>{1, -2, 3}));
  EXPECT_THROW(a.data<float>(), std::runtime_error);
}

std::string Header(const std::string& dict) {
  std::string h = dict;
  while ((10 + h.size() + 1) % 64) h += ' ';
  h += '\n';
  std::string out("\x93NUMPY\x01\x00", 8);
  out.push_back(static_cast<char>(h.size()));
  out.push_back(0);
  return out + h;
}

TEST(Npy, RefusesWhatItCannotRead) {
  auto message = [](const std::string& bytes) {
    try {
      ParseNpy(bytes, "x.npy");
    } catch (const std::runtime_error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(message("garbage").find("bad magic"), std::string::npos);
  EXPECT_NE(message(Header("{'descr': '<f4', 'fortran_order': True, 'shape': (2,), }") + std::string(8, '\0'))
                .find("Fortran"),
            std::string::npos);
  EXPECT_NE(message(Header("{'descr': '>f4', 'fortran_order': False, 'shape': (2,), }") + std::string(8, '\0'))
                .find("unsupported dtype"),
            std::string::npos);
  EXPECT_NE(message(Header("{'descr': '<c8', 'fortran_order': False, 'shape': (2,), }") + std::string(16, '\0'))
                .find("unsupported dtype"),
            std::string::npos);
  EXPECT_NE(message(Header("{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3), }") + std::string(8, '\0'))
                .find("truncated data"),
            std::string::npos);
  EXPECT_EQ(message(Header("{'descr': '<f4', 'fortran_order': False, 'shape': (2,), }") + std::string(8, '\0')),
            "no error");
  // int16 (the compact bases of shipped head models): two values, -2 and 300.
  const NpyArray i16 =
      ParseNpy(Header("{'descr': '<i2', 'fortran_order': False, 'shape': (2,), }") + std::string("\xfe\xff\x2c\x01", 4),
               "i16.npy");
  EXPECT_EQ(i16.dtype(), DType::kInt16);
  EXPECT_EQ(i16.ToFloats(), (std::vector<float>{-2.f, 300.f}));
  EXPECT_NE(message("x.npy").find("x.npy"), std::string::npos);  // errors name the source
}

std::string MessageOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::runtime_error& e) {
    return e.what();
  } catch (const std::exception& e) {
    return std::string("wrong exception type: ") + e.what();
  }
  return "no error";
}

long PeakRssMb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss / 1024;
}

TEST(Npy, ForgedShapesAreRefusedBeforeAllocating) {
  const long before = PeakRssMb();
  const std::string data(8, '\0');
  // 2e9 floats claimed by an 8-byte payload: refused, not an 8 GB allocation.
  EXPECT_NE(MessageOf([&] {
              ParseNpy(Header("{'descr': '<f4', 'fortran_order': False, 'shape': (2000000000,), }") + data, "x");
            }).find("truncated data"),
            std::string::npos);
  // A product that wraps to zero in 64 bits must not pass as an empty array.
  EXPECT_NE(MessageOf([&] {
              ParseNpy(Header("{'descr': '<f4', 'fortran_order': False, 'shape': (4294967296, 4294967296), }") + data,
                       "x");
            }).find("truncated data"),
            std::string::npos);
  // 1e15 elements: a clear error naming the source, not std::bad_alloc.
  EXPECT_NE(MessageOf([&] {
              ParseNpy(Header("{'descr': '<f8', 'fortran_order': False, 'shape': (1000000000000000,), }") + data,
                       "x.npy");
            }).find("x.npy"),
            std::string::npos);
  EXPECT_THROW(NpyArray(DType::kFloat64, {int64_t(1) << 40, 1 << 20}), std::invalid_argument);
  EXPECT_LT(PeakRssMb() - before, 200);
}

// Sets the uncompressed size of every entry in a zip's local and central headers.
void ForgeUncompressedSize(const std::string& path, uint32_t size) {
  std::string bytes = ReadFileBytes(path);
  const auto patch = [&](const char* signature, size_t field) {
    for (size_t at = bytes.find(signature, 0, 4); at != std::string::npos; at = bytes.find(signature, at + 4, 4))
      std::memcpy(&bytes[at + field], &size, 4);
  };
  patch("PK\x03\x04", 22);
  patch("PK\x01\x02", 24);
  std::ofstream(path, std::ios::binary) << bytes;
}

TEST(Files, AFullDiskIsAnErrorAndLeavesTheOldFile) {
  const std::string dir = testing::TempDir("full");
  WriteFileAtomically(dir + "/state.json", "old");
  // The temporary file lands on /dev/full: every write fails with ENOSPC, which
  // a buffered stream reports only when it is flushed at close.
  std::filesystem::create_symlink("/dev/full", dir + "/state.json.tmp");
  const std::string message = MessageOf([&] { WriteFileAtomically(dir + "/state.json", "new"); });
  EXPECT_NE(message.find("disk full"), std::string::npos) << message;
  EXPECT_EQ(ReadFileBytes(dir + "/state.json"), "old");
}

TEST(Npz, CorruptBitsFailTheCrc) {
  const std::string dir = testing::TempDir("crc");
  std::vector<float> values(1000);
  for (size_t i = 0; i < values.size(); ++i) values[i] = 0.25f * static_cast<float>(i);
  NpzArchive a;
  a["x"] = NpyArray::From<float>({1000}, values.data());
  WriteNpz(dir + "/a.npz", a, /*compress=*/false);
  std::string bytes = ReadFileBytes(dir + "/a.npz");
  const float probe = 0.25f * 500;
  char pattern[4];
  std::memcpy(pattern, &probe, 4);
  const size_t at = bytes.find(std::string(pattern, 4));
  ASSERT_NE(at, std::string::npos);
  bytes[at] ^= 0x01;  // one flipped bit in the array's data
  std::ofstream(dir + "/a.npz", std::ios::binary) << bytes;
  const std::string message = MessageOf([&] { ReadNpz(dir + "/a.npz"); });
  EXPECT_NE(message.find("CRC"), std::string::npos) << message;
  EXPECT_NE(message.find("a.npz"), std::string::npos) << message;
}

TEST(Zip, ForgedSizesAndBombsAreRefusedBeforeUnpacking) {
  const std::string dir = testing::TempDir("bomb");
  const long before = PeakRssMb();
  // A stored 4 KB entry whose headers claim 3 GB.
  WriteZip(dir + "/forged.zip", {{"a", std::string(4096, 'a')}}, /*compress=*/false);
  ForgeUncompressedSize(dir + "/forged.zip", 3000000000u);
  std::string message = MessageOf([&] { ReadZip(dir + "/forged.zip"); });
  EXPECT_NE(message.find("forged.zip:a"), std::string::npos) << message;
  EXPECT_LT(PeakRssMb() - before, 100);  // nothing was allocated for the claim
  // 200 MB of zeros deflated to a few hundred KB: a zip bomb.
  WriteZip(dir + "/bomb.zip", {{"zeros", std::string(200u << 20, '\0')}});
  message = MessageOf([&] { ReadZip(dir + "/bomb.zip"); });
  EXPECT_NE(message.find("zip bomb"), std::string::npos) << message;
  // Highly compressible but modest content still loads: 16 MB of zeros (a fresh texture, say).
  WriteZip(dir + "/zeros.zip", {{"zeros", std::string(16u << 20, '\0')}});
  EXPECT_EQ(ReadZip(dir + "/zeros.zip").at("zeros").size(), 16u << 20);
}

TEST(Npz, RoundTripAndStrings) {
  const std::string dir = testing::TempDir("npz");
  const std::string path = dir + "/a.npz";
  NpzArchive a;
  const std::vector<float> f = {1, 2, 3, 4, 5, 6};
  a["floats"] = NpyArray::From<float>({2, 3}, f.data());
  a["names"] = StringsToNpy({"smile", "jawOpen", ""});
  const int64_t big = int64_t(1) << 50;
  a["big"] = NpyArray::From<int64_t>({1}, &big);
  WriteNpz(path, a);
  const NpzArchive b = ReadNpz(path);
  ASSERT_EQ(b.size(), 3u);
  EXPECT_EQ(b.at("floats").shape(), (std::vector<int64_t>{2, 3}));
  EXPECT_EQ(b.at("floats").ToFloats(), f);
  EXPECT_EQ(NpyToStrings(b.at("names")), (std::vector<std::string>{"smile", "jawOpen", ""}));
  EXPECT_EQ(b.at("big").data<int64_t>()[0], big);
  EXPECT_FALSE(std::filesystem::exists(path + ".tmp"));
}

TEST(Npz, TruncatedMissingAndForeignFilesAreRefusedByName) {
  const std::string dir = testing::TempDir("bad");
  NpzArchive a;
  std::vector<float> big(20000, 1.f);
  a["x"] = NpyArray::From<float>({20000}, big.data());
  WriteNpz(dir + "/good.npz", a, /*compress=*/false);
  const auto size = std::filesystem::file_size(dir + "/good.npz");
  std::filesystem::copy_file(dir + "/good.npz", dir + "/cut.npz");
  std::filesystem::resize_file(dir + "/cut.npz", size / 2);
  { std::ofstream(dir + "/foreign.npz") << "hello, not a zip"; }
  for (const std::string name : {"cut.npz", "foreign.npz", "missing.npz"}) {
    try {
      ReadNpz(dir + "/" + name);
      ADD_FAILURE() << name << " was accepted";
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find(name), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace headcast
