#include "fmv3d/io/colmap_model.h"

#include <fmt/format.h>

#include <fstream>
#include <sstream>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"

namespace fmv3d::io {
namespace {

using fmv3d::Error;

std::string G(double v) { return fmt::format("{:.17g}", v); }

// Reads the non-comment, non-empty lines of a COLMAP text file.
std::vector<std::string> DataLines(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in) throw Error(path.string() + ": cannot open (expected a COLMAP text model file)");
  std::vector<std::string> lines;
  std::string line;
  while (std::getline(in, line)) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    const auto first = line.find_first_not_of(" \t");
    if (first == std::string::npos || line[first] == '#') {
      // images.txt has two lines per image and the second may be empty: keep empty lines there.
      if (first == std::string::npos && path.filename() == "images.txt") lines.push_back("");
      continue;
    }
    lines.push_back(line);
  }
  return lines;
}

core::Camera ParseCamera(const std::string& line, const std::string& where) {
  std::istringstream ss(line);
  core::Camera c;
  std::string model;
  if (!(ss >> c.id >> model >> c.width >> c.height)) throw Error(where + ": malformed camera line: " + line);
  std::vector<double> p;
  double v;
  while (ss >> v) p.push_back(v);
  auto need = [&](size_t n) {
    if (p.size() != n)
      throw Error(where + ": camera " + std::to_string(c.id) + " model " + model + " needs " + std::to_string(n) +
                  " parameters, found " + std::to_string(p.size()));
  };
  if (model == "SIMPLE_PINHOLE") {
    need(3);
    c.f = p[0], c.u0 = p[1], c.v0 = p[2];
  } else if (model == "PINHOLE") {
    need(4);
    c.f = p[1], c.aspect = p[0] / p[1], c.u0 = p[2], c.v0 = p[3];
  } else if (model == "SIMPLE_RADIAL") {
    need(4);
    c.f = p[0], c.u0 = p[1], c.v0 = p[2], c.k1 = p[3];
  } else if (model == "RADIAL") {
    need(5);
    c.f = p[0], c.u0 = p[1], c.v0 = p[2], c.k1 = p[3], c.k2 = p[4];
  } else if (model == "OPENCV") {
    need(8);
    c.f = p[1], c.aspect = p[0] / p[1], c.u0 = p[2], c.v0 = p[3];
    c.k1 = p[4], c.k2 = p[5], c.p1 = p[6], c.p2 = p[7];
  } else {
    throw Error(where + ": camera model " + model + " is not supported (use OPENCV, RADIAL or PINHOLE)");
  }
  return c;
}

}  // namespace

void WriteColmapText(const core::Reconstruction& rec, const std::filesystem::path& dir) {
  core::EnsureDirectory(dir);
  std::ostringstream cams;
  cams << "# Camera list with one line of data per camera:\n"
       << "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
       << "# Number of cameras: " << rec.cameras.size() << "\n";
  for (const auto& [id, c] : rec.cameras)
    cams << id << " OPENCV " << c.width << " " << c.height << " " << G(c.fx()) << " " << G(c.fy()) << " " << G(c.u0)
         << " " << G(c.v0) << " " << G(c.k1) << " " << G(c.k2) << " " << G(c.p1) << " " << G(c.p2) << "\n";

  size_t n_obs = 0;
  for (const auto& [id, im] : rec.images)
    for (int64_t p : im.point3d_ids) n_obs += p != core::kNoPoint3D;
  std::ostringstream ims;
  ims << "# Image list with two lines of data per image:\n"
      << "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
      << "#   POINTS2D[] as (X, Y, POINT3D_ID)\n"
      << "# Number of images: " << rec.images.size() << ", mean observations per image: "
      << (rec.images.empty() ? 0.0 : static_cast<double>(n_obs) / rec.images.size()) << "\n";
  for (const auto& [id, im] : rec.images) {
    const auto& q = im.pose.q;
    const auto& t = im.pose.t;
    ims << id << " " << G(q.w()) << " " << G(q.x()) << " " << G(q.y()) << " " << G(q.z()) << " " << G(t.x()) << " "
        << G(t.y()) << " " << G(t.z()) << " " << im.camera_id << " " << im.name << "\n";
    for (size_t i = 0; i < im.points2d.size(); ++i) {
      if (i) ims << " ";
      ims << G(im.points2d[i].x()) << " " << G(im.points2d[i].y()) << " " << im.point3d_ids[i];
    }
    ims << "\n";
  }

  std::ostringstream pts;
  pts << "# 3D point list with one line of data per point:\n"
      << "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n"
      << "# Number of points: " << rec.points.size() << ", mean track length: " << rec.MeanTrackLength() << "\n";
  for (const auto& [id, p] : rec.points) {
    pts << id << " " << G(p.xyz.x()) << " " << G(p.xyz.y()) << " " << G(p.xyz.z()) << " " << int(p.rgb[0]) << " "
        << int(p.rgb[1]) << " " << int(p.rgb[2]) << " " << G(p.error);
    for (const auto& el : p.track) pts << " " << el.image_id << " " << el.point2d_idx;
    pts << "\n";
  }
  core::WriteTextFile(dir / "cameras.txt", cams.str());
  core::WriteTextFile(dir / "images.txt", ims.str());
  core::WriteTextFile(dir / "points3D.txt", pts.str());
}

core::Reconstruction ReadColmapText(const std::filesystem::path& dir) {
  core::Reconstruction rec;
  const auto cam_path = dir / "cameras.txt";
  for (const auto& line : DataLines(cam_path)) {
    core::Camera c = ParseCamera(line, cam_path.string());
    rec.cameras[c.id] = c;
  }

  const auto im_path = dir / "images.txt";
  const auto lines = DataLines(im_path);
  size_t i = 0;
  while (i < lines.size()) {
    if (lines[i].empty()) {
      ++i;
      continue;
    }
    std::istringstream ss(lines[i]);
    core::Image im;
    double qw, qx, qy, qz, tx, ty, tz;
    if (!(ss >> im.id >> qw >> qx >> qy >> qz >> tx >> ty >> tz >> im.camera_id))
      throw Error(im_path.string() + ": malformed image line: " + lines[i]);
    std::getline(ss >> std::ws, im.name);
    if (im.name.empty()) throw Error(im_path.string() + ": image " + std::to_string(im.id) + " has no name");
    im.pose.q = Eigen::Quaterniond(qw, qx, qy, qz);  // keep as stored: normalising would change the bits
    im.pose.t = Eigen::Vector3d(tx, ty, tz);
    if (i + 1 < lines.size()) {
      std::istringstream ps(lines[i + 1]);
      double x, y;
      int64_t pid;
      while (ps >> x >> y >> pid) {
        im.points2d.emplace_back(x, y);
        im.point3d_ids.push_back(pid);
      }
    }
    rec.images[im.id] = std::move(im);
    i += 2;
  }

  const auto pt_path = dir / "points3D.txt";
  for (const auto& line : DataLines(pt_path)) {
    std::istringstream ss(line);
    core::Point3D p;
    int r, g, b;
    if (!(ss >> p.id >> p.xyz.x() >> p.xyz.y() >> p.xyz.z() >> r >> g >> b >> p.error))
      throw Error(pt_path.string() + ": malformed point line: " + line.substr(0, 80));
    p.rgb << static_cast<uint8_t>(r), static_cast<uint8_t>(g), static_cast<uint8_t>(b);
    core::TrackElement el;
    while (ss >> el.image_id >> el.point2d_idx) p.track.push_back(el);
    rec.points[p.id] = std::move(p);
  }
  rec.Validate();
  return rec;
}

}  // namespace fmv3d::io
