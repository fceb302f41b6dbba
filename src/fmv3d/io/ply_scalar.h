#pragma once
// The scalar types of the PLY format and how their bytes decode: shared by the whole-cloud reader
// (io/point_cloud) and the streaming vertex reader (io/ply_stream).
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <optional>
#include <string_view>

namespace fmv3d::io::ply {

enum class Scalar { kI8, kU8, kI16, kU16, kI32, kU32, kF32, kF64 };

// Both spellings of the PLY specification ("uchar" and "uint8"); nullopt for anything else.
inline std::optional<Scalar> ScalarFromName(std::string_view t) {
  if (t == "char" || t == "int8") return Scalar::kI8;
  if (t == "uchar" || t == "uint8") return Scalar::kU8;
  if (t == "short" || t == "int16") return Scalar::kI16;
  if (t == "ushort" || t == "uint16") return Scalar::kU16;
  if (t == "int" || t == "int32") return Scalar::kI32;
  if (t == "uint" || t == "uint32") return Scalar::kU32;
  if (t == "float" || t == "float32") return Scalar::kF32;
  if (t == "double" || t == "float64") return Scalar::kF64;
  return std::nullopt;
}

inline size_t SizeOf(Scalar t) {
  switch (t) {
    case Scalar::kI8:
    case Scalar::kU8:
      return 1;
    case Scalar::kI16:
    case Scalar::kU16:
      return 2;
    case Scalar::kI32:
    case Scalar::kU32:
    case Scalar::kF32:
      return 4;
    case Scalar::kF64:
      return 8;
  }
  return 0;
}

namespace detail {
template <typename T>
double Load(const char* p) {
  T v;
  std::memcpy(&v, p, sizeof v);
  return static_cast<double>(v);
}
}  // namespace detail

// The value of SizeOf(t) bytes at p, in the host's byte order (callers swap big-endian data first).
inline double Decode(Scalar t, const char* p) {
  switch (t) {
    case Scalar::kI8:
      return detail::Load<int8_t>(p);
    case Scalar::kU8:
      return detail::Load<uint8_t>(p);
    case Scalar::kI16:
      return detail::Load<int16_t>(p);
    case Scalar::kU16:
      return detail::Load<uint16_t>(p);
    case Scalar::kI32:
      return detail::Load<int32_t>(p);
    case Scalar::kU32:
      return detail::Load<uint32_t>(p);
    case Scalar::kF32:
      return detail::Load<float>(p);
    case Scalar::kF64:
      return detail::Load<double>(p);
  }
  return 0;
}

}  // namespace fmv3d::io::ply
