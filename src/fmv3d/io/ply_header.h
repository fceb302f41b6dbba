#pragma once
// A PLY file's header (format, elements and their properties), read once for every PLY reader: the whole-cloud
// reader (io/point_cloud) and the streaming vertex reader (io/ply_stream).
#include <cstddef>
#include <istream>
#include <string>
#include <vector>

#include "fmv3d/io/ply_scalar.h"

namespace fmv3d::io::ply {

enum class Format { kAscii, kBinaryLittleEndian, kBinaryBigEndian };

struct Property {
  std::string name;
  bool is_list = false;
  Scalar count_type = Scalar::kU8;  // lists only
  Scalar type = Scalar::kF32;       // the scalar's type, or the list items' type
};

struct Element {
  std::string name;
  size_t count = 0;
  std::vector<Property> properties;
  // Index of the non-list property called `name` (or of the list when `list`), -1 when absent.
  int Find(const std::string& name, bool list = false) const;
};

struct Header {
  Format format = Format::kAscii;
  std::vector<Element> elements;
};

// Reads the header from the start of `in`, leaving it at the first data byte. Throws fmv3d::Error naming `file`
// on anything that is not a well-formed PLY header (magic, format, element counts, property types, end_header).
Header ReadHeader(std::istream& in, const std::string& file);

// Throws fmv3d::Error when the elements' counts need more bytes than the `data_bytes` after the header (an ascii
// value takes at least 2 bytes, a binary one its size), so a corrupt count is an error, not a huge allocation.
void CheckCountsFit(const Header& header, unsigned long long data_bytes, const std::string& file);

}  // namespace fmv3d::io::ply
