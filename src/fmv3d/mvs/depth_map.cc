#include "fmv3d/mvs/depth_map.h"

#include <algorithm>
#include <cstring>
#include <fstream>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/io/image_io.h"

namespace fmv3d::mvs {
namespace {
constexpr char kMagic[8] = {'F', 'M', 'V', 'D', 'M', 'A', 'P', '\0'};
constexpr uint32_t kVersion = 1;
}  // namespace

int DepthMap::CountValid() const { return depth.empty() ? 0 : cv::countNonZero(depth > 0); }

void WriteDepthMap(const DepthMap& map, const std::filesystem::path& path) {
  core::WriteAtomically(path, [&](const std::filesystem::path& tmp) {
    std::ofstream out(tmp, std::ios::binary);
    if (!out) throw Error(tmp.string() + ": cannot write");
    const int32_t w = map.width(), h = map.height();
    out.write(kMagic, sizeof kMagic);
    out.write(reinterpret_cast<const char*>(&kVersion), 4);
    out.write(reinterpret_cast<const char*>(&w), 4);
    out.write(reinterpret_cast<const char*>(&h), 4);
    for (const cv::Mat* m : {&map.depth, &map.normal, &map.cost}) {
      const cv::Mat c = m->isContinuous() ? *m : m->clone();
      out.write(reinterpret_cast<const char*>(c.data), static_cast<std::streamsize>(c.total() * c.elemSize()));
    }
    if (!out) throw Error(tmp.string() + ": write failed");
  });
}

DepthMap ReadDepthMap(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(path.string() + ": cannot open depth map");
  char magic[8];
  uint32_t version = 0;
  int32_t w = 0, h = 0;
  in.read(magic, 8);
  in.read(reinterpret_cast<char*>(&version), 4);
  in.read(reinterpret_cast<char*>(&w), 4);
  in.read(reinterpret_cast<char*>(&h), 4);
  if (!in || std::memcmp(magic, kMagic, 8) != 0) throw Error(path.string() + ": not an fmv3d depth map");
  if (version != kVersion)
    throw Error(path.string() + ": depth map version " + std::to_string(version) + ", expected " +
                std::to_string(kVersion) + " (re-run `fmv3d dense`)");
  if (w <= 0 || h <= 0 || w > 100000 || h > 100000 || static_cast<int64_t>(w) * h > 400000000)
    throw Error(path.string() + ": implausible depth map size " + std::to_string(w) + "x" + std::to_string(h));
  const auto expected = 20 + static_cast<uint64_t>(w) * h * 4 * 5;  // header: magic 8, version, w, h
  std::error_code ec;
  if (std::filesystem::file_size(path, ec) != expected)
    throw Error(path.string() + ": truncated or oversized depth map (expected " + std::to_string(expected) + " bytes)");
  DepthMap m;
  m.depth.create(h, w, CV_32F);
  m.normal.create(h, w, CV_32FC3);
  m.cost.create(h, w, CV_32F);
  for (cv::Mat* mat : {&m.depth, &m.normal, &m.cost})
    in.read(reinterpret_cast<char*>(mat->data), static_cast<std::streamsize>(mat->total() * mat->elemSize()));
  if (!in) throw Error(path.string() + ": truncated depth map");
  return m;
}

void WriteDepthPreview(const DepthMap& map, const std::filesystem::path& depth_png,
                       const std::filesystem::path& normal_png) {
  std::vector<float> valid;
  for (int y = 0; y < map.height(); ++y)
    for (int x = 0; x < map.width(); ++x)
      if (map.depth.at<float>(y, x) > 0) valid.push_back(map.depth.at<float>(y, x));
  float lo = 0, hi = 1;
  if (!valid.empty()) {
    std::sort(valid.begin(), valid.end());
    lo = valid[valid.size() / 50];
    hi = valid[valid.size() - 1 - valid.size() / 50];
    if (!(hi > lo)) hi = lo + 1;
  }
  cv::Mat gray(map.height(), map.width(), CV_8U), normal(map.height(), map.width(), CV_8UC3);
  for (int y = 0; y < map.height(); ++y) {
    for (int x = 0; x < map.width(); ++x) {
      const float d = map.depth.at<float>(y, x);
      gray.at<uint8_t>(y, x) = static_cast<uint8_t>(std::clamp(255.f * (d - lo) / (hi - lo), 0.f, 255.f));
      const cv::Vec3f n = map.normal.at<cv::Vec3f>(y, x);
      cv::Vec3b c(0, 0, 0);
      if (d > 0)
        for (int k = 0; k < 3; ++k) c[2 - k] = static_cast<uint8_t>(std::clamp(127.5f * (n[k] + 1), 0.f, 255.f));
      normal.at<cv::Vec3b>(y, x) = c;
    }
  }
  cv::Mat color;
  cv::applyColorMap(gray, color, cv::COLORMAP_TURBO);
  color.setTo(cv::Scalar(0, 0, 0), map.depth <= 0);
  io::WriteImage(depth_png, color);
  io::WriteImage(normal_png, normal);
}

}  // namespace fmv3d::mvs
