#include "fmv3d/io/ply_header.h"

#include <algorithm>
#include <sstream>

#include "fmv3d/core/error.h"

namespace fmv3d::io::ply {
namespace {

Scalar ParseType(const std::string& s, const std::string& file) {
  if (const auto t = ScalarFromName(s)) return *t;
  throw Error(file + ": unknown PLY property type '" + s + "'");
}

}  // namespace

int Element::Find(const std::string& n, bool list) const {
  for (size_t k = 0; k < properties.size(); ++k)
    if (properties[k].name == n && properties[k].is_list == list) return static_cast<int>(k);
  return -1;
}

Header ReadHeader(std::istream& in, const std::string& file) {
  std::string line;
  if (!std::getline(in, line) || line.rfind("ply", 0) != 0) throw Error(file + ": not a PLY file");
  Header h;
  bool has_format = false;
  while (true) {
    if (!std::getline(in, line)) throw Error(file + ": PLY header has no end_header");
    if (!line.empty() && line.back() == '\r') line.pop_back();
    std::istringstream ls(line);
    std::string word;
    ls >> word;
    if (word == "end_header") break;
    if (word == "format") {
      std::string f;
      ls >> f;
      if (f == "ascii")
        h.format = Format::kAscii;
      else if (f == "binary_little_endian")
        h.format = Format::kBinaryLittleEndian;
      else if (f == "binary_big_endian")
        h.format = Format::kBinaryBigEndian;
      else
        throw Error(std::string(file).append(": unknown PLY format '").append(f).append("'"));
      has_format = true;
    } else if (word == "element") {
      Element e;
      long long count = -1;
      ls >> e.name >> count;
      if (count < 0 || count > (1LL << 34)) throw Error(file + ": bad PLY element count");
      e.count = static_cast<size_t>(count);
      // Readers look elements up by name: a second "vertex" would be read over the first with other columns.
      for (const Element& earlier : h.elements)
        if (earlier.name == e.name) throw Error(file + ": PLY element '" + e.name + "' declared twice");
      h.elements.push_back(e);
    } else if (word == "property") {
      if (h.elements.empty()) throw Error(file + ": PLY property before any element");
      Property p;
      std::string t;
      ls >> t;
      if (t == "list") {
        std::string ct, it;
        ls >> ct >> it >> p.name;
        p.is_list = true;
        p.count_type = ParseType(ct, file);
        p.type = ParseType(it, file);
      } else {
        p.type = ParseType(t, file);
        ls >> p.name;
      }
      h.elements.back().properties.push_back(p);
    }
  }
  if (!has_format) throw Error(file + ": PLY header has no format line");
  return h;
}

void CheckCountsFit(const Header& header, unsigned long long data_bytes, const std::string& file) {
  unsigned long long needed = 0;
  for (const Element& e : header.elements) {
    unsigned long long record = 0;
    for (const Property& p : e.properties)
      record += header.format == Format::kAscii ? 2 : SizeOf(p.is_list ? p.count_type : p.type);
    needed += e.count * std::max<unsigned long long>(record, 1);
    if (needed > data_bytes)
      throw Error(file + ": truncated PLY: element '" + e.name + "' needs at least " + std::to_string(needed) +
                  " bytes of data, the file has " + std::to_string(data_bytes));
  }
}

}  // namespace fmv3d::io::ply
