#include "fmv3d/io/image_io.h"

#include <algorithm>
#include <cctype>
#include <fstream>
#include <vector>

#include <opencv2/imgcodecs.hpp>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"

namespace fmv3d::io {
namespace {

std::string LowerExt(const std::filesystem::path& p) {
  std::string e = p.extension().string();
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return std::tolower(c); });
  return e;
}

// Minimal bounds-checked TIFF/EXIF IFD reader.
class TiffReader {
 public:
  TiffReader(const unsigned char* d, size_t n) : d_(d), n_(n) {}
  bool Init() {
    if (n_ < 8) return false;
    if (d_[0] == 'I' && d_[1] == 'I') le_ = true;
    else if (d_[0] == 'M' && d_[1] == 'M') le_ = false;
    else return false;
    return U16(2) == 42;
  }
  uint32_t FirstIfd() const { return U32(4); }
  bool Ok(size_t off, size_t len) const { return off <= n_ && len <= n_ - off; }
  uint16_t U16(size_t o) const {
    if (!Ok(o, 2)) return 0;
    return le_ ? uint16_t(d_[o] | d_[o + 1] << 8) : uint16_t(d_[o] << 8 | d_[o + 1]);
  }
  uint32_t U32(size_t o) const {
    if (!Ok(o, 4)) return 0;
    return le_ ? uint32_t(d_[o]) | uint32_t(d_[o + 1]) << 8 | uint32_t(d_[o + 2]) << 16 | uint32_t(d_[o + 3]) << 24
               : uint32_t(d_[o]) << 24 | uint32_t(d_[o + 1]) << 16 | uint32_t(d_[o + 2]) << 8 | uint32_t(d_[o + 3]);
  }
  struct Entry {
    uint16_t tag, type;
    uint32_t count;
    size_t value_offset;  // where the value bytes are (inline or pointed to)
  };
  // Calls fn(entry) for each entry of the IFD at `off`.
  template <typename Fn>
  void ForEach(uint32_t off, Fn fn) const {
    if (!Ok(off, 2)) return;
    const int n = U16(off);
    for (int i = 0; i < n && i < 1000; ++i) {
      const size_t e = off + 2 + 12 * size_t(i);
      if (!Ok(e, 12)) return;
      Entry en{U16(e), U16(e + 2), U32(e + 4), 0};
      static const int kSize[] = {0, 1, 1, 2, 4, 8, 1, 1, 2, 4, 8, 4, 8};
      const size_t unit = en.type < 13 ? kSize[en.type] : 0;
      if (unit == 0) continue;
      const uint64_t bytes = uint64_t(unit) * en.count;
      en.value_offset = bytes <= 4 ? e + 8 : U32(e + 8);
      if (bytes > n_ || !Ok(en.value_offset, size_t(bytes))) continue;
      fn(en);
    }
  }
  std::string Ascii(const Entry& e) const {
    if (e.type != 2) return "";
    std::string s(reinterpret_cast<const char*>(d_ + e.value_offset), e.count);
    s.erase(std::find(s.begin(), s.end(), '\0'), s.end());
    while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.pop_back();
    while (!s.empty() && std::isspace(static_cast<unsigned char>(s.front()))) s.erase(s.begin());
    return s;
  }
  double Number(const Entry& e) const {
    switch (e.type) {
      case 3: return U16(e.value_offset);
      case 4: return U32(e.value_offset);
      case 5: {
        const uint32_t num = U32(e.value_offset), den = U32(e.value_offset + 4);
        return den ? double(num) / den : 0;
      }
      default: return 0;
    }
  }

 private:
  const unsigned char* d_;
  size_t n_;
  bool le_ = true;
};

}  // namespace

bool HasImageExtension(const std::filesystem::path& path) {
  static const char* kExt[] = {".bmp", ".png", ".jpg", ".jpeg", ".gif", ".tif", ".tiff"};
  const std::string e = LowerExt(path);
  return std::any_of(std::begin(kExt), std::end(kExt), [&](const char* k) { return e == k; });
}

bool HasVideoExtension(const std::filesystem::path& path) {
  static const char* kExt[] = {".mp4", ".m4v", ".avi", ".mpg", ".mpeg", ".ts",  ".m2ts", ".mts", ".mov",
                               ".mkv", ".webm", ".wmv", ".flv", ".3gp", ".mxf", ".vob", ".ogv"};
  const std::string e = LowerExt(path);
  return std::any_of(std::begin(kExt), std::end(kExt), [&](const char* k) { return e == k; });
}

cv::Mat ReadImage(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) throw Error(path.string() + ": no such image file");
  if (LowerExt(path) == ".gif")  // OpenCV 4.6 has no GIF decoder
    throw Error(path.string() + ": GIF is decoded through FFmpeg by ingest::ReadInputImage (or `fmv3d frames`)");
  cv::Mat img;
  try {
    img = cv::imread(path.string(), cv::IMREAD_COLOR | cv::IMREAD_IGNORE_ORIENTATION);
  } catch (const cv::Exception& e) {
    throw Error(path.string() + ": cannot decode image (" + e.what() + ")");
  }
  if (img.empty()) throw Error(path.string() + ": cannot decode image (unsupported or corrupt file)");
  return img;
}

cv::Size ReadImageSize(const std::filesystem::path& path) {
  // Decoding is the only fully reliable way across formats; images are read once during ingestion anyway.
  const cv::Mat img = ReadImage(path);
  return img.size();
}

void WriteImage(const std::filesystem::path& path, const cv::Mat& image) {
  core::WriteAtomically(path, [&](const std::filesystem::path& tmp) {
    std::vector<int> params;
    if (LowerExt(path) == ".png") params = {cv::IMWRITE_PNG_COMPRESSION, 1};  // zlib level dominates ingestion time
    bool ok = false;
    try {
      ok = cv::imwrite(tmp.string(), image, params);
    } catch (const cv::Exception& e) {
      throw Error(path.string() + ": cannot write image (" + e.what() + ")");
    }
    if (!ok) throw Error(path.string() + ": cannot write image");
  });
}

ExifInfo ParseTiffExif(const unsigned char* data, size_t size) {
  ExifInfo info;
  TiffReader r(data, size);
  if (!r.Init()) return info;
  uint32_t exif_ifd = 0;
  r.ForEach(r.FirstIfd(), [&](const TiffReader::Entry& e) {
    if (e.tag == 0x010F) info.make = r.Ascii(e);
    if (e.tag == 0x0110) info.model = r.Ascii(e);
    if (e.tag == 0x8769) exif_ifd = static_cast<uint32_t>(r.Number(e));
    if (e.tag == 0x920A) info.focal_mm = r.Number(e);  // TIFF/EP puts it in IFD0
  });
  double fp_res = 0;
  int fp_unit = 2;
  if (exif_ifd) {
    r.ForEach(exif_ifd, [&](const TiffReader::Entry& e) {
      if (e.tag == 0x920A) info.focal_mm = r.Number(e);
      if (e.tag == 0xA405) info.focal_35mm = r.Number(e);
      if (e.tag == 0xA20E) fp_res = r.Number(e);
      if (e.tag == 0xA210) fp_unit = static_cast<int>(r.Number(e));
      if (e.tag == 0xA002) info.pixel_width = static_cast<int>(r.Number(e));
    });
  }
  // FocalPlaneResolutionUnit: 2 inch, 3 cm, 4 mm, 5 µm.
  const double per_mm = fp_unit == 2 ? 1 / 25.4 : fp_unit == 3 ? 0.1 : fp_unit == 4 ? 1.0 : fp_unit == 5 ? 1000.0 : 0;
  info.focal_plane_x_res = fp_res * per_mm;
  if (!(info.focal_mm > 0 && info.focal_mm < 5000)) info.focal_mm = 0;
  if (!(info.focal_35mm > 0 && info.focal_35mm < 5000)) info.focal_35mm = 0;
  return info;
}

ExifInfo ReadExif(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return {};
  const std::string ext = LowerExt(path);
  if (ext == ".tif" || ext == ".tiff") {
    std::vector<unsigned char> buf(1 << 18);
    in.read(reinterpret_cast<char*>(buf.data()), buf.size());
    buf.resize(static_cast<size_t>(in.gcount()));
    return ParseTiffExif(buf.data(), buf.size());
  }
  // JPEG: walk the markers up to the first scan looking for APP1 "Exif\0\0".
  unsigned char soi[2];
  if (!in.read(reinterpret_cast<char*>(soi), 2) || soi[0] != 0xFF || soi[1] != 0xD8) return {};
  for (int guard = 0; guard < 64; ++guard) {
    unsigned char m[4];
    if (!in.read(reinterpret_cast<char*>(m), 4) || m[0] != 0xFF) return {};
    const int marker = m[1];
    const size_t len = size_t(m[2]) << 8 | m[3];
    if (marker == 0xDA || marker == 0xD9 || len < 2) return {};
    std::vector<unsigned char> seg(len - 2);
    if (!in.read(reinterpret_cast<char*>(seg.data()), seg.size())) return {};
    if (marker == 0xE1 && seg.size() > 6 && std::equal(seg.begin(), seg.begin() + 6, "Exif\0\0"))
      return ParseTiffExif(seg.data() + 6, seg.size() - 6);
  }
  return {};
}

}  // namespace fmv3d::io
