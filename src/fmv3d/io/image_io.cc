#include "fmv3d/io/image_io.h"

#include <algorithm>
#include <cctype>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <vector>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"

namespace fmv3d::io {
namespace {

std::string LowerExt(const std::filesystem::path& p) {
  std::string e = p.extension().string();
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return std::tolower(c); });
  return e;
}

}  // namespace

bool HasImageExtension(const std::filesystem::path& path) {
  static const char* kExt[] = {".bmp", ".png", ".jpg", ".jpeg", ".gif", ".tif", ".tiff"};
  const std::string e = LowerExt(path);
  return std::any_of(std::begin(kExt), std::end(kExt), [&](const char* k) { return e == k; });
}

bool HasVideoExtension(const std::filesystem::path& path) {
  static const char* kExt[] = {".mp4", ".m4v",  ".avi", ".mpg", ".mpeg", ".ts",  ".m2ts", ".mts", ".mov",
                               ".mkv", ".webm", ".wmv", ".flv", ".3gp",  ".mxf", ".vob",  ".ogv"};
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

}  // namespace fmv3d::io
