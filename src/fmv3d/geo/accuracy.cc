#include "fmv3d/geo/accuracy.h"

#include <cmath>

namespace fmv3d::geo {

double GeorefAccuracy::HeightSigma(const Eigen::Vector3d& d) const {
  // A small rotation w about the pivot moves the point by w × d: its height by w_x·d_y − w_y·d_x.
  const Eigen::Vector3d g(d.y(), -d.x(), 0);
  const double var = position_cov(2, 2) + g.dot(rotation_cov * g) + std::pow(d.z() * scale_sigma_rel, 2);
  return std::sqrt(std::max(0.0, var));
}

namespace {

nlohmann::json Rows(const Eigen::Matrix3d& m, double factor) {
  nlohmann::json rows = nlohmann::json::array();
  for (int r = 0; r < 3; ++r) rows.push_back({m(r, 0) * factor, m(r, 1) * factor, m(r, 2) * factor});
  return rows;
}

bool ReadRows(const nlohmann::json& j, double factor, Eigen::Matrix3d* m) {
  if (!j.is_array() || j.size() != 3) return false;
  for (int r = 0; r < 3; ++r) {
    if (!j[r].is_array() || j[r].size() != 3) return false;
    for (int c = 0; c < 3; ++c) {
      if (!j[r][c].is_number()) return false;
      (*m)(r, c) = j[r][c].get<double>() / factor;
    }
  }
  return m->allFinite();
}

constexpr double kDeg2 = (180 / M_PI) * (180 / M_PI);

}  // namespace

nlohmann::json GeorefAccuracy::ToJson() const {
  nlohmann::json j = {{"pivot_enu", {pivot.x(), pivot.y(), pivot.z()}},
                      {"position_cov_m2", Rows(position_cov, 1)},
                      {"horizontal_m", std::sqrt(std::max(0.0, position_cov(0, 0) + position_cov(1, 1)))},
                      {"vertical_m", std::sqrt(std::max(0.0, position_cov(2, 2)))},
                      {"scale_sigma_relative", scale_sigma_rel},
                      {"rotation_known", rotation_known},
                      {"from", from},
                      {"note",
                       "1σ, from the telemetry's own scatter and effective sample counts; the model's own "
                       "shape error is not included"}};
  if (rotation_known) {
    j["rotation_cov_deg2"] = Rows(rotation_cov, kDeg2);
    j["tilt_deg"] = std::sqrt(std::max(0.0, (rotation_cov(0, 0) + rotation_cov(1, 1)) * kDeg2));
    j["heading_deg"] = std::sqrt(std::max(0.0, rotation_cov(2, 2) * kDeg2));
  }
  return j;
}

std::optional<GeorefAccuracy> GeorefAccuracy::FromJson(const nlohmann::json& j) {
  if (!j.is_object() || !j.contains("pivot_enu") || !j.contains("position_cov_m2")) return std::nullopt;
  GeorefAccuracy a;
  const auto& p = j["pivot_enu"];
  if (!p.is_array() || p.size() != 3 || !p[0].is_number() || !p[1].is_number() || !p[2].is_number())
    return std::nullopt;
  a.pivot = Eigen::Vector3d(p[0].get<double>(), p[1].get<double>(), p[2].get<double>());
  if (!ReadRows(j["position_cov_m2"], 1, &a.position_cov)) return std::nullopt;
  a.scale_sigma_rel = j.value("scale_sigma_relative", 0.0);
  a.rotation_known = j.value("rotation_known", false) && j.contains("rotation_cov_deg2") &&
                     ReadRows(j["rotation_cov_deg2"], kDeg2, &a.rotation_cov);
  if (j.contains("from") && j["from"].is_array())
    for (const auto& s : j["from"])
      if (s.is_string()) a.from.push_back(s.get<std::string>());
  return a;
}

Eigen::Matrix3d RotationInformation(const std::vector<Eigen::Vector3d>& points, double sigma) {
  Eigen::Matrix3d info = Eigen::Matrix3d::Zero();
  if (points.empty() || !(sigma > 0)) return info;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& p : points) mean += p;
  mean /= static_cast<double>(points.size());
  for (const auto& p : points) {
    const Eigen::Vector3d d = p - mean;
    Eigen::Matrix3d dx;  // w × d = −[d]× w
    dx << 0, -d.z(), d.y(), d.z(), 0, -d.x(), -d.y(), d.x(), 0;
    info += dx.transpose() * dx;
  }
  return info / (sigma * sigma);
}

}  // namespace fmv3d::geo
