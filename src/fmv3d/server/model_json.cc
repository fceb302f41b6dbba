#include "fmv3d/server/model_json.h"

#include <cmath>

namespace fmv3d::server {

nlohmann::json CamerasJson(const core::Reconstruction& rec) {
  nlohmann::json out = nlohmann::json::array();
  for (const auto& [id, im] : rec.images) {
    const auto cam_it = rec.cameras.find(im.camera_id);
    if (cam_it == rec.cameras.end()) continue;
    const core::Camera& cam = cam_it->second;
    const Eigen::Matrix3d R = im.pose.R();
    double sq = 0;
    int n = 0;
    for (size_t k = 0; k < im.points2d.size() && k < im.point3d_ids.size(); ++k) {
      const auto p = rec.points.find(static_cast<uint64_t>(im.point3d_ids[k]));
      if (im.point3d_ids[k] == core::kNoPoint3D || p == rec.points.end()) continue;
      const Eigen::Vector3d x = R * p->second.xyz + im.pose.t;
      if (x.z() <= 0) continue;
      sq += (cam.Project(x) - im.points2d[k]).squaredNorm();
      ++n;
    }
    const Eigen::Vector3d c = -R.transpose() * im.pose.t;
    const Eigen::Quaterniond q = im.pose.q.normalized();
    out.push_back({{"name", im.name},
                   {"width", cam.width},
                   {"height", cam.height},
                   {"fx", cam.fx()},
                   {"fy", cam.fy()},
                   {"cx", cam.u0},
                   {"cy", cam.v0},
                   {"center", {c.x(), c.y(), c.z()}},
                   {"rotation", {q.w(), q.x(), q.y(), q.z()}},
                   {"reprojection_rms_px", n ? nlohmann::json(std::sqrt(sq / n)) : nlohmann::json()},
                   {"frame", "frames/" + im.name}});
  }
  return out;
}

nlohmann::json SparseJson(const core::Reconstruction& rec) {
  std::vector<float> positions, errors;
  std::vector<int> colors;
  positions.reserve(rec.points.size() * 3);
  colors.reserve(rec.points.size() * 3);
  errors.reserve(rec.points.size());
  for (const auto& [id, p] : rec.points) {
    for (int k = 0; k < 3; ++k) positions.push_back(static_cast<float>(p.xyz[k]));
    for (int k = 0; k < 3; ++k) colors.push_back(p.rgb[k]);
    errors.push_back(static_cast<float>(p.error));
  }
  return {{"count", rec.points.size()}, {"positions", positions}, {"colors", colors}, {"errors", errors}};
}

}  // namespace fmv3d::server
