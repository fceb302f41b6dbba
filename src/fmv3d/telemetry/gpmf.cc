#include "fmv3d/telemetry/gpmf.h"

#include <cmath>
#include <cstring>
#include <limits>

namespace fmv3d::telemetry::gpmf {
namespace {

constexpr int kMaxDepth = 8;

uint64_t BigEndian(const uint8_t* p, size_t n) {
  uint64_t v = 0;
  for (size_t i = 0; i < n; ++i) v = v << 8 | p[i];
  return v;
}

// One element of type t at p (TypeSize(t) bytes available); NaN for non-numeric types.
double Element(char t, const uint8_t* p) {
  switch (t) {
    case 'b':
      return static_cast<int8_t>(p[0]);
    case 'B':
      return p[0];
    case 'c':
      return static_cast<char>(p[0]);
    case 's':
      return static_cast<int16_t>(BigEndian(p, 2));
    case 'S':
      return static_cast<uint16_t>(BigEndian(p, 2));
    case 'l':
      return static_cast<int32_t>(BigEndian(p, 4));
    case 'L':
      return static_cast<uint32_t>(BigEndian(p, 4));
    case 'j':
      return static_cast<double>(static_cast<int64_t>(BigEndian(p, 8)));
    case 'J':
      return static_cast<double>(BigEndian(p, 8));
    case 'q':
      return static_cast<int32_t>(BigEndian(p, 4)) / 65536.0;
    case 'Q':
      return static_cast<double>(static_cast<int64_t>(BigEndian(p, 8))) / 4294967296.0;
    case 'f': {
      const uint32_t u = static_cast<uint32_t>(BigEndian(p, 4));
      float f;
      std::memcpy(&f, &u, 4);
      return f;
    }
    case 'd': {
      const uint64_t u = BigEndian(p, 8);
      double d;
      std::memcpy(&d, &u, 8);
      return d;
    }
    default:
      return std::numeric_limits<double>::quiet_NaN();
  }
}

std::string FourCC(const uint8_t* p) {
  std::string s(reinterpret_cast<const char*>(p), 4);
  for (char& c : s)
    if (static_cast<unsigned char>(c) < 0x20 || static_cast<unsigned char>(c) > 0x7E) c = '?';
  return s;
}

// Text of a 'c' entry: NULs and trailing spaces removed.
std::string Text(const uint8_t* p, size_t n) {
  std::string s;
  for (size_t i = 0; i < n; ++i)
    if (p[i] != 0) s.push_back(static_cast<char>(p[i]));
  while (!s.empty() && s.back() == ' ') s.pop_back();
  return s;
}

struct Header {
  std::string key;
  char type = 0;
  size_t ssize = 0, repeat = 0;
  const uint8_t* data = nullptr;
  size_t size() const { return ssize * repeat; }
};

// The sticky state of a STRM while its entries are read.
struct StreamState {
  std::vector<double> scale;
  std::string type;  // expanded TYPE
  std::vector<std::string> units, si_units;
  std::string name;
  std::optional<double> gps_fix, gps_dop;
  std::string gps_utc, altitude_system;
  std::optional<uint64_t> stmp_us;
};

struct DeviceState {
  std::string name;
  uint32_t id = 0;
};

class Parser {
 public:
  Parser(std::vector<Stream>* out, ParseStats* stats) : out_(out), stats_(stats) {}

  // Reads the entries in [p, p + n) at `depth`; `stream` is the enclosing STRM's state (null outside one).
  void Level(const uint8_t* p, size_t n, int depth, DeviceState* device, StreamState* stream) {
    if (depth > kMaxDepth) {
      ++stats_->malformed;
      return;
    }
    size_t pos = 0;
    while (n - pos >= 8) {
      Header h;
      h.key = FourCC(p + pos);
      h.type = static_cast<char>(p[pos + 4]);
      h.ssize = p[pos + 5];
      h.repeat = static_cast<size_t>(BigEndian(p + pos + 6, 2));
      if (BigEndian(p + pos, 4) == 0) return;  // zero padding at the end of a payload
      const size_t size = h.size();            // at most 255 · 65535: no overflow
      if (size > n - pos - 8) {
        ++stats_->malformed;
        return;  // the rest of this level cannot be trusted
      }
      h.data = p + pos + 8;
      ++stats_->entries;
      Entry(h, depth, device, stream);
      const size_t padded = (size + 3) & ~size_t(3);
      if (padded > n - pos - 8) return;  // the last entry's padding may be cut off
      pos += 8 + padded;
    }
  }

 private:
  void Entry(const Header& h, int depth, DeviceState* device, StreamState* stream) {
    if (h.type == 0) {  // nested
      if (h.key == "DEVC") {
        DeviceState d;
        Level(h.data, h.size(), depth + 1, &d, nullptr);
      } else if (h.key == "STRM") {
        StreamState s;
        DeviceState none;
        Level(h.data, h.size(), depth + 1, device ? device : &none, &s);
      } else {
        Level(h.data, h.size(), depth + 1, device, stream);
      }
      return;
    }
    if (device && h.key == "DVNM" && h.type == 'c') device->name = Text(h.data, h.size());
    if (device && h.key == "DVID" && h.type == 'L' && h.size() >= 4)
      device->id = static_cast<uint32_t>(BigEndian(h.data, 4));
    if (!stream) return;
    if (Sticky(h, stream)) return;
    Data(h, *device, *stream);
  }

  // Sticky metadata of a stream; false for anything else (data).
  bool Sticky(const Header& h, StreamState* s) {
    const std::string& k = h.key;
    if (k == "SCAL") {
      s->scale = Numbers(h);
    } else if (k == "TYPE") {
      const auto t = ExpandType(Text(h.data, h.size()));
      if (!t) ++stats_->malformed;
      s->type = t.value_or("");
    } else if (k == "UNIT" || k == "SIUN") {
      std::vector<std::string> u;
      if (h.type == 'c' && h.ssize > 0)
        for (size_t i = 0; i < h.repeat; ++i) u.push_back(Text(h.data + i * h.ssize, h.ssize));
      (k == "UNIT" ? s->units : s->si_units) = std::move(u);
    } else if (k == "STNM") {
      s->name = h.type == 'c' ? Text(h.data, h.size()) : "";
    } else if (k == "GPSF") {
      const auto v = Numbers(h);
      if (!v.empty()) s->gps_fix = v[0];
    } else if (k == "GPSP") {
      const auto v = Numbers(h);
      if (!v.empty()) s->gps_dop = v[0] / 100.0;
    } else if (k == "GPSU") {
      s->gps_utc = Text(h.data, h.size());
    } else if (k == "GPSA") {
      s->altitude_system = h.type == 'F' && h.size() >= 4 ? FourCC(h.data) : Text(h.data, h.size());
    } else if (k == "STMP") {
      const auto v = Numbers(h);
      if (!v.empty() && v[0] >= 0 && v[0] < 1.8e19) s->stmp_us = static_cast<uint64_t>(v[0]);
    } else if (k == "TSMP" || k == "TICK" || k == "TOCK" || k == "EMPT" || k == "TMPC" || k == "ORIN" || k == "ORIO" ||
               k == "MTRX" || k == "TIMO" || k == "DVID" || k == "DVNM" || k == "RMRK" || k == "MTYP" || k == "QUAN") {
      // Timing, temperature, orientation matrices, remarks: not needed for telemetry samples.
    } else {
      return false;
    }
    return true;
  }

  // All numbers of a simple-typed entry (used for sticky values).
  std::vector<double> Numbers(const Header& h) {
    std::vector<double> v;
    const size_t ts = TypeSize(h.type);
    if (ts == 0 || h.type == 'c' || h.type == 'U' || h.type == 'F' || h.type == 'G') return v;
    const size_t n = h.size() / ts;
    v.reserve(n);
    for (size_t i = 0; i < n; ++i) v.push_back(Element(h.type, h.data + i * ts));
    return v;
  }

  void Data(const Header& h, const DeviceState& device, const StreamState& s) {
    if (h.type == 'c' || h.type == 'U' || h.type == 'F' || h.type == 'G') {
      ++stats_->unsupported;  // text and identifiers are not samples
      return;
    }
    std::string layout;  // element types of one sample
    if (h.type == '?') {
      if (s.type.empty()) {
        ++stats_->malformed;
        return;
      }
      layout = s.type;
    } else {
      const size_t ts = TypeSize(h.type);
      if (ts == 0 || h.ssize % ts != 0 || h.ssize == 0) {
        ++(ts == 0 ? stats_->unsupported : stats_->malformed);
        return;
      }
      layout.assign(h.ssize / ts, h.type);
    }
    size_t bytes = 0;
    for (char t : layout) {
      const size_t ts = TypeSize(t);
      if (ts == 0) {
        ++stats_->malformed;
        return;
      }
      bytes += ts;
    }
    if (bytes != h.ssize) {
      ++stats_->malformed;
      return;
    }
    Stream st;
    st.device = device.name;
    st.device_id = device.id;
    st.key = h.key;
    st.name = s.name;
    st.units = s.si_units.empty() ? s.units : s.si_units;
    st.type = h.type == '?' ? layout : std::string();
    st.elements = layout.size();
    st.gps_fix = s.gps_fix;
    st.gps_dop = s.gps_dop;
    st.gps_utc = s.gps_utc;
    st.altitude_system = s.altitude_system;
    st.stmp_us = s.stmp_us;
    st.values.reserve(h.repeat * layout.size());
    for (size_t r = 0; r < h.repeat; ++r) {
      const uint8_t* q = h.data + r * h.ssize;
      for (size_t e = 0; e < layout.size(); ++e) {
        double v = Element(layout[e], q);
        q += TypeSize(layout[e]);
        const double sc = s.scale.size() == layout.size() ? s.scale[e] : s.scale.size() == 1 ? s.scale[0] : 1.0;
        if (sc != 0 && std::isfinite(sc)) v /= sc;
        st.values.push_back(v);
      }
    }
    out_->push_back(std::move(st));
  }

  std::vector<Stream>* out_;
  ParseStats* stats_;
};

}  // namespace

size_t TypeSize(char t) {
  switch (t) {
    case 'b':
    case 'B':
    case 'c':
      return 1;
    case 's':
    case 'S':
      return 2;
    case 'l':
    case 'L':
    case 'f':
    case 'q':
    case 'F':
      return 4;
    case 'd':
    case 'j':
    case 'J':
    case 'Q':
      return 8;
    case 'G':
    case 'U':
      return 16;
    default:
      return 0;
  }
}

std::optional<std::string> ExpandType(const std::string& type, size_t max) {
  std::string out;
  for (size_t i = 0; i < type.size(); ++i) {
    const char t = type[i];
    if (t == '[') return std::nullopt;  // an array without an element type
    size_t count = 1;
    if (i + 1 < type.size() && type[i + 1] == '[') {
      const size_t close = type.find(']', i + 2);
      if (close == std::string::npos || close == i + 2 || close - i > 8) return std::nullopt;
      count = 0;
      for (size_t k = i + 2; k < close; ++k) {
        if (type[k] < '0' || type[k] > '9') return std::nullopt;
        count = count * 10 + static_cast<size_t>(type[k] - '0');
      }
      i = close;
    }
    if (TypeSize(t) == 0 || count > max || out.size() + count > max) return std::nullopt;
    out.append(count, t);
  }
  return out;
}

std::vector<Stream> ParsePayload(const uint8_t* data, size_t size, ParseStats* stats) {
  ParseStats local;
  std::vector<Stream> out;
  if (!data || size == 0) return out;
  Parser(&out, stats ? stats : &local).Level(data, size, 0, nullptr, nullptr);
  return out;
}

}  // namespace fmv3d::telemetry::gpmf
