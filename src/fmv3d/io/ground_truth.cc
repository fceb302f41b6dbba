#include "fmv3d/io/ground_truth.h"

#include <fmt/format.h>

#include <algorithm>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <regex>

#include "fmv3d/core/error.h"

namespace fmv3d::io {
namespace {

namespace fs = std::filesystem;

std::vector<double> ReadNumbers(const fs::path& path) {
  std::ifstream in(path);
  if (!in) throw Error(path.string() + ": cannot open");
  std::vector<double> v;
  double x;
  while (in >> x) v.push_back(x);
  return v;
}

// Returns the id of a camera equal to `cam` (same K and size), adding it if new.
uint32_t AddCamera(core::Reconstruction& rec, core::Camera cam) {
  for (const auto& [id, c] : rec.cameras)
    if (c.width == cam.width && c.height == cam.height && c.Params() == cam.Params()) return id;
  cam.id = static_cast<uint32_t>(rec.cameras.size() + 1);
  rec.cameras[cam.id] = cam;
  return cam.id;
}

core::Camera CameraFromK(const Eigen::Matrix3d& K, int width, int height) {
  core::Camera c;
  c.width = width;
  c.height = height;
  c.f = K(1, 1);
  c.aspect = K(0, 0) / K(1, 1);
  c.u0 = K(0, 2) + 0.5;
  c.v0 = K(1, 2) + 0.5;
  c.Validate();
  return c;
}

// Nearest rotation to a matrix printed with few digits.
Eigen::Matrix3d Orthonormalize(const Eigen::Matrix3d& M, const std::string& name) {
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(M, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Matrix3d R = svd.matrixU() * svd.matrixV().transpose();
  if (R.determinant() < 0) throw Error(name + ": ground-truth rotation is a reflection");
  return R;
}

// R is world-to-camera, already orthonormal.
void AddImage(core::Reconstruction& rec, const std::string& name, uint32_t camera_id, const Eigen::Matrix3d& R,
              const Eigen::Vector3d& t) {
  core::Image im;
  im.id = static_cast<uint32_t>(rec.images.size() + 1);
  im.camera_id = camera_id;
  im.name = name;
  im.pose = core::Pose(Eigen::Quaterniond(R), t);
  rec.images[im.id] = im;
}

}  // namespace

core::Reconstruction ReadStrechaCameras(const fs::path& dir) {
  if (!fs::is_directory(dir)) throw Error(dir.string() + ": not a folder of .camera files");
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.path().extension() == ".camera") files.push_back(e.path());
  std::sort(files.begin(), files.end());
  if (files.empty()) throw Error(dir.string() + ": no .camera files");
  core::Reconstruction rec;
  for (const auto& f : files) {
    const auto v = ReadNumbers(f);
    if (v.size() != 9 + 3 + 9 + 3 + 2)
      throw Error(f.string() + ": expected 26 numbers (K, distortion, R, C, size), found " + std::to_string(v.size()));
    Eigen::Matrix3d K = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(v.data());
    Eigen::Matrix3d R_cw = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(v.data() + 12);
    const Eigen::Vector3d C(v[21], v[22], v[23]);
    core::Camera cam = CameraFromK(K, static_cast<int>(v[24]), static_cast<int>(v[25]));
    cam.k1 = v[9];
    cam.k2 = v[10];
    const Eigen::Matrix3d R = Orthonormalize(R_cw.transpose(), f.string());
    AddImage(rec, f.stem().string(), AddCamera(rec, cam), R, -R * C);
  }
  return rec;
}

core::Reconstruction ReadMiddleburyPar(const fs::path& par_file) {
  std::ifstream in(par_file);
  if (!in) throw Error(par_file.string() + ": cannot open");
  int n = 0;
  if (!(in >> n) || n <= 0) throw Error(par_file.string() + ": first line must be the number of images");
  core::Reconstruction rec;
  for (int i = 0; i < n; ++i) {
    std::string name;
    double v[21];
    if (!(in >> name)) throw Error(par_file.string() + ": expected " + std::to_string(n) + " images");
    for (double& x : v)
      if (!(in >> x)) throw Error(par_file.string() + ": malformed line for " + name);
    int width = 640, height = 480;
    const fs::path img = par_file.parent_path() / name;
    if (fs::exists(img)) {
      const cv::Mat m = cv::imread(img.string(), cv::IMREAD_UNCHANGED);
      if (!m.empty()) width = m.cols, height = m.rows;
    }
    Eigen::Matrix3d K = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(v);
    const Eigen::Matrix3d R =
        Orthonormalize(Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(v + 9), name);
    AddImage(rec, name, AddCamera(rec, CameraFromK(K, width, height)), R, Eigen::Vector3d(v[18], v[19], v[20]));
  }
  return rec;
}

core::Reconstruction ReadKrtdFolder(const fs::path& dir, int width, int height, int index_offset,
                                    const std::string& ext) {
  if (!fs::is_directory(dir)) throw Error(dir.string() + ": not a folder of .krtd files");
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.path().extension() == ".krtd") files.push_back(e.path());
  std::sort(files.begin(), files.end());
  if (files.empty()) throw Error(dir.string() + ": no .krtd files");
  const std::regex name_re("(.*)-([0-9]+)");
  core::Reconstruction rec;
  for (const auto& f : files) {
    const auto v = ReadNumbers(f);
    if (v.size() < 9 + 9 + 3 + 1) throw Error(f.string() + ": expected K, R, t and distortion");
    Eigen::Matrix3d K = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(v.data());
    const Eigen::Matrix3d R =
        Orthonormalize(Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(v.data() + 9), f.string());
    const Eigen::Vector3d t(v[18], v[19], v[20]);
    core::Camera cam = CameraFromK(K, width, height);
    const size_t nd = v.size() - 21;
    if (nd >= 1) cam.k1 = v[21];
    if (nd >= 2) cam.k2 = v[22];
    if (nd >= 4) cam.p1 = v[23], cam.p2 = v[24];
    std::smatch m;
    const std::string stem = f.stem().string();
    std::string name = stem + ext;
    if (std::regex_match(stem, m, name_re))
      name = fmt::format("{}-{:06d}{}", m[1].str(), std::stol(m[2].str()) - index_offset, ext);
    AddImage(rec, name, AddCamera(rec, cam), R, t);
  }
  return rec;
}

}  // namespace fmv3d::io
