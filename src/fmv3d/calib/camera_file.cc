#include "fmv3d/calib/camera_file.h"

#include <algorithm>
#include <cmath>
#include <opencv2/core/persistence.hpp>

#include "fmv3d/core/camera_json.h"
#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"

namespace fmv3d::calib {
namespace fs = std::filesystem;

void WriteCameraJson(const fs::path& path, const CalibrationResult& r) {
  const core::Camera& c = r.camera;
  nlohmann::json j = core::CameraToJson(c);
  j["version"] = 1;
  j["model"] = "fmv3d-brown";
  j["pixel_convention"] = "pixel centres at +0.5 (COLMAP)";
  j["rms"] = r.rms;
  static const char* kNames[] = {"f", "aspect", "u0", "v0", "k1", "k2", "p1", "p2"};
  for (int i = 0; i < core::kNumIntrinsics; ++i) j["stddev"][kNames[i]] = r.stddev[i];
  j["images"] = nlohmann::json::array();
  for (size_t i = 0; i < r.used.size(); ++i) {
    nlohmann::json im = {{"name", r.used[i]}, {"rms", i < r.per_image_rms.size() ? r.per_image_rms[i] : 0.0}};
    auto flat = [](const std::vector<Eigen::Vector2d>& v) {
      std::vector<double> out;
      for (const auto& p : v) out.push_back(p.x()), out.push_back(p.y());
      return out;
    };
    if (i < r.corners.size()) im["corners"] = flat(r.corners[i]);
    if (i < r.residuals.size()) im["residuals"] = flat(r.residuals[i]);
    j["images"].push_back(im);
  }
  j["rejected"] = r.rejected;
  j["board"] = {{"cols", r.board.cols}, {"rows", r.board.rows}, {"square", r.board.square}};
  core::WriteJson(path, j);
}

void WriteOpenCvYaml(const fs::path& path, const core::Camera& c, double rms) {
  core::WriteAtomically(path, [&](const fs::path& tmp) {
    cv::FileStorage fsw(tmp.string(), cv::FileStorage::WRITE | cv::FileStorage::FORMAT_YAML);
    if (!fsw.isOpened()) throw Error(path.string() + ": cannot write");
    cv::Mat K = (cv::Mat_<double>(3, 3) << c.fx(), 0, c.u0 - 0.5, 0, c.fy(), c.v0 - 0.5, 0, 0, 1);
    cv::Mat d = (cv::Mat_<double>(1, 5) << c.k1, c.k2, c.p1, c.p2, 0.0);
    fsw << "image_width" << c.width << "image_height" << c.height << "camera_matrix" << K << "distortion_coefficients"
        << d;
    if (rms >= 0) fsw << "avg_reprojection_error" << rms;
    fsw.release();
  });
}

core::Camera ReadCameraFile(const fs::path& path) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char ch) { return std::tolower(ch); });
  core::Camera c;
  if (ext == ".yaml" || ext == ".yml" || ext == ".xml") {
    if (!fs::is_regular_file(path)) throw Error(path.string() + ": no such calibration file");
    cv::FileStorage fsr;
    try {
      fsr.open(path.string(), cv::FileStorage::READ);
    } catch (const cv::Exception& e) {
      throw Error(path.string() + ": not a readable OpenCV calibration file (" + e.what() + ")");
    }
    if (!fsr.isOpened()) throw Error(path.string() + ": not a readable OpenCV calibration file");
    cv::Mat K, d;
    fsr["camera_matrix"] >> K;
    fsr["distortion_coefficients"] >> d;
    fsr["image_width"] >> c.width;
    fsr["image_height"] >> c.height;
    if (K.rows != 3 || K.cols != 3)
      throw Error(path.string() + ": no 3x3 camera_matrix (expected OpenCV calibration output)");
    K.convertTo(K, CV_64F);
    d.convertTo(d, CV_64F);
    c.f = K.at<double>(1, 1);
    c.aspect = K.at<double>(0, 0) / c.f;
    c.u0 = K.at<double>(0, 2) + 0.5;
    c.v0 = K.at<double>(1, 2) + 0.5;
    const double* dp = d.empty() ? nullptr : d.ptr<double>();
    const size_t nd = d.total();
    if (nd > 4 && std::abs(dp[4]) > 1e-12)
      throw Error(path.string() + ": has k3 != 0, which fmv3d's camera model (k1 k2 p1 p2) cannot represent");
    if (nd >= 1) c.k1 = dp[0];
    if (nd >= 2) c.k2 = dp[1];
    if (nd >= 3) c.p1 = dp[2];
    if (nd >= 4) c.p2 = dp[3];
  } else {
    const nlohmann::json j = core::ReadJson(path);
    try {
      c.width = j.at("width").get<int>();
      c.height = j.at("height").get<int>();
      core::IntrinsicsFromJson(j, &c);
    } catch (const nlohmann::json::exception& e) {
      throw Error(path.string() + ": not a camera file (" + e.what() + ")");
    }
  }
  try {
    c.Validate();
  } catch (const Error& e) {
    throw Error(path.string() + ": " + e.what());
  }
  return c;
}

bool ScaleCamera(const core::Camera& c, int width, int height, core::Camera* out) {
  if (c.width <= 0 || c.height <= 0 || width <= 0 || height <= 0) return false;
  const double sx = double(width) / c.width, sy = double(height) / c.height;
  if (std::abs(sx / sy - 1) > 0.01) return false;
  *out = c.Resized(width, height);
  return true;
}

}  // namespace fmv3d::calib
