#pragma once
// Byte-level codec of the map file (map_file.hpp): CRC-32, a little-endian writer, and a
// bounds-checked little-endian reader whose errors name the file, the section and the byte offset.
// Kept apart from the record layout so each file has one job.
#include <fmt/format.h>

#include <Eigen/Core>
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "stillpoint/common/error.hpp"
#include "stillpoint/map/types.hpp"

namespace sp::map {

// CRC-32 (IEEE 802.3, reflected polynomial 0xEDB88320, as zlib's crc32). `crc` continues a running
// checksum: crc32(b, crc32(a)) == crc32(a + b).
std::uint32_t crc32(std::span<const std::uint8_t> bytes, std::uint32_t crc = 0);

// Little-endian unsigned integer at p (sizeof(T) bytes), and the inverse.
template <typename T>
T load_le(const std::uint8_t* p) {
  T v = 0;
  for (std::size_t i = 0; i < sizeof(T); ++i) v |= static_cast<T>(T{p[i]} << (8U * i));
  return v;
}
template <typename T>
void store_le(std::uint8_t* p, T v) {
  for (std::size_t i = 0; i < sizeof(T); ++i) p[i] = static_cast<std::uint8_t>(v >> (8U * i));
}

class ByteWriter {
 public:
  void u8(std::uint8_t v) { buf_.push_back(v); }
  void u32(std::uint32_t v) { put(v); }
  void u64(std::uint64_t v) { put(v); }
  template <class Tag>
  void id(Id<Tag> v) {
    put(v.value());
  }
  void i32(std::int32_t v) { u32(static_cast<std::uint32_t>(v)); }
  void f32(float v) { u32(std::bit_cast<std::uint32_t>(v)); }
  void f64(double v) { u64(std::bit_cast<std::uint64_t>(v)); }
  void bytes(const std::uint8_t* p, std::size_t n) { buf_.insert(buf_.end(), p, p + n); }
  void str(const std::string& s) {
    u32(static_cast<std::uint32_t>(s.size()));
    bytes(reinterpret_cast<const std::uint8_t*>(s.data()), s.size());
  }
  void vec3(const Eigen::Vector3d& v) {
    f64(v.x());
    f64(v.y());
    f64(v.z());
  }
  std::vector<std::uint8_t>& buffer() { return buf_; }

 private:
  template <typename T>
  void put(T v) {
    buf_.resize(buf_.size() + sizeof(T));
    store_le(buf_.data() + buf_.size() - sizeof(T), v);
  }
  std::vector<std::uint8_t> buf_;
};

// Bounds-checked little-endian reader over one section's payload; errors name the file, the
// section and the absolute byte offset.
class ByteReader {
 public:
  ByteReader(std::span<const std::uint8_t> data, std::size_t base, std::string file, std::string section)
      : data_(data), base_(base), file_(std::move(file)), section_(std::move(section)) {}

  [[noreturn]] void fail(const std::string& what) const {
    throw InputError(file_, 0, fmt::format("section {} at byte offset {}: {}", section_, base_ + pos_, what));
  }
  void need(std::size_t n) const {
    if (data_.size() - pos_ < n)
      fail(fmt::format("record runs past the end of the section ({} bytes needed, {} left)", n,
                       data_.size() - pos_));
  }
  // Guards a count read from the file against the bytes left before anything is allocated for it.
  void need_records(std::uint64_t count, std::size_t min_record_bytes) const {
    if (count > (data_.size() - pos_) / std::max<std::size_t>(1, min_record_bytes))
      fail(fmt::format("count {} does not fit in the {} bytes left", count, data_.size() - pos_));
  }
  std::uint8_t u8() {
    need(1);
    return data_[pos_++];
  }
  std::uint32_t u32() { return get<std::uint32_t>(); }
  std::uint64_t u64() { return get<std::uint64_t>(); }
  template <class IdType>
  IdType id() {
    return IdType{get<std::uint64_t>()};
  }
  std::int32_t i32() { return static_cast<std::int32_t>(u32()); }
  float f32() { return std::bit_cast<float>(u32()); }
  double f64() { return std::bit_cast<double>(u64()); }
  double finite64(const char* what) {
    const double v = f64();
    if (!std::isfinite(v)) fail(fmt::format("{} is not finite", what));
    return v;
  }
  float finite32(const char* what) {
    const float v = f32();
    if (!std::isfinite(v)) fail(fmt::format("{} is not finite", what));
    return v;
  }
  Eigen::Vector3d vec3(const char* what) {
    Eigen::Vector3d v;
    v.x() = finite64(what);
    v.y() = finite64(what);
    v.z() = finite64(what);
    return v;
  }
  const std::uint8_t* bytes(std::size_t n) {
    need(n);
    const std::uint8_t* p = data_.data() + pos_;
    pos_ += n;
    return p;
  }
  std::string str(std::size_t max_len) {
    const std::uint32_t n = u32();
    if (n > max_len) fail(fmt::format("string of {} bytes (at most {})", n, max_len));
    const auto* p = bytes(n);
    return {reinterpret_cast<const char*>(p), n};
  }
  void expect_end() const {
    if (pos_ != data_.size())
      fail(fmt::format("{} unexpected bytes after the last record", data_.size() - pos_));
  }
  [[nodiscard]] const std::string& file() const { return file_; }
  [[nodiscard]] const std::string& section() const { return section_; }

 private:
  template <typename T>
  T get() {
    need(sizeof(T));
    const T v = load_le<T>(data_.data() + pos_);
    pos_ += sizeof(T);
    return v;
  }
  std::span<const std::uint8_t> data_;
  std::size_t base_;
  std::size_t pos_ = 0;
  std::string file_;
  std::string section_;
};

}  // namespace sp::map
