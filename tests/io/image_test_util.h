// Test helpers for EXIF: a hand-built TIFF/EXIF block and its insertion into a JPEG file (header-only, also
// used by tests/calib).
#pragma once

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

namespace fmv3d::test {

// A little-endian TIFF/EXIF block: IFD0 with Make, Model and the EXIF IFD pointer; the EXIF IFD with
// FocalLength (rational) and FocalLengthIn35mmFilm (short).
inline std::vector<unsigned char> MakeExif(const std::string& make, const std::string& model, uint32_t focal_num,
                                           uint32_t focal_den, uint16_t focal35) {
  std::vector<unsigned char> b;
  auto u16 = [&](uint16_t v) { b.push_back(v & 0xFF), b.push_back(v >> 8); };
  auto u32 = [&](uint32_t v) {
    for (int i = 0; i < 4; ++i) b.push_back((v >> (8 * i)) & 0xFF);
  };
  const uint32_t ifd0 = 8, ifd0_size = 2 + 3 * 12 + 4;
  const uint32_t make_off = ifd0 + ifd0_size, model_off = make_off + uint32_t(make.size()) + 1;
  uint32_t exif_off = model_off + uint32_t(model.size()) + 1;
  exif_off += exif_off % 2;
  const uint32_t rational_off = exif_off + 2 + 2 * 12 + 4;
  b = {'I', 'I'};
  u16(42);
  u32(ifd0);
  u16(3);
  // Values of up to 4 bytes sit in the entry itself (TIFF 6.0), longer ones at an offset.
  auto ascii_entry = [&](uint16_t tag, const std::string& s, uint32_t off) {
    u16(tag), u16(2), u32(uint32_t(s.size()) + 1);
    if (s.size() + 1 <= 4) {
      for (size_t i = 0; i < 4; ++i) b.push_back(i < s.size() ? s[i] : 0);
    } else {
      u32(off);
    }
  };
  ascii_entry(0x010F, make, make_off);
  ascii_entry(0x0110, model, model_off);
  u16(0x8769), u16(4), u32(1), u32(exif_off);
  u32(0);
  for (char c : make) b.push_back(c);
  b.push_back(0);
  for (char c : model) b.push_back(c);
  b.push_back(0);
  while (b.size() < exif_off) b.push_back(0);
  u16(2);
  u16(0x920A), u16(5), u32(1), u32(rational_off);
  u16(0xA405), u16(3), u32(1), u16(focal35), u16(0);
  u32(0);
  u32(focal_num), u32(focal_den);
  return b;
}

// Inserts an APP1 Exif segment right after the SOI of a JPEG file.
inline void AddExifToJpeg(const std::filesystem::path& path, const std::vector<unsigned char>& tiff) {
  std::ifstream in(path, std::ios::binary);
  std::vector<unsigned char> jpg((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::vector<unsigned char> seg = {0xFF, 0xE1, 0, 0, 'E', 'x', 'i', 'f', 0, 0};
  seg.insert(seg.end(), tiff.begin(), tiff.end());
  const size_t len = seg.size() - 2;
  seg[2] = static_cast<unsigned char>(len >> 8);
  seg[3] = static_cast<unsigned char>(len & 0xFF);
  jpg.insert(jpg.begin() + 2, seg.begin(), seg.end());
  std::ofstream(path, std::ios::binary).write(reinterpret_cast<const char*>(jpg.data()), jpg.size());
}

}  // namespace fmv3d::test
