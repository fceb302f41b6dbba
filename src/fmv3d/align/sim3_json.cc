#include "fmv3d/align/sim3_json.h"

#include <cmath>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"

namespace fmv3d::align {

nlohmann::json Sim3ToJson(const core::Sim3& sim) {
  const Eigen::Matrix3d R = sim.q.toRotationMatrix();
  nlohmann::json rot = nlohmann::json::array();
  for (int r = 0; r < 3; ++r) rot.push_back({R(r, 0), R(r, 1), R(r, 2)});
  return {{"scale", sim.s}, {"rotation", rot}, {"translation", {sim.t.x(), sim.t.y(), sim.t.z()}}};
}

core::Sim3 Sim3FromJson(const nlohmann::json& j_in) {
  const char* shape =
      "expected {\"scale\": s, \"rotation\": [[3x3]], \"translation\": [x, y, z]} (or \"q_wxyz\" and \"t\", "
      "or a report with such an \"alignment\")";
  // A report that carries the similarity (e.g. report/sparse_eval.json of `fmv3d evaluate-sparse`).
  const nlohmann::json& j = j_in.is_object() && j_in.contains("alignment") ? j_in.at("alignment") : j_in;
  const char* rkey = j.is_object() && j.contains("rotation") ? "rotation" : "q_wxyz";
  const char* tkey = j.is_object() && j.contains("translation") ? "translation" : "t";
  if (!j.is_object() || !j.contains("scale") || !j.contains(rkey) || !j.contains(tkey))
    throw Error(std::string("similarity: ") + shape);
  core::Sim3 sim;
  Eigen::Matrix3d R;
  try {
    sim.s = j.at("scale").get<double>();
    const auto& rot = j.at(rkey);
    const auto& t = j.at(tkey);
    if (!t.is_array() || t.size() != 3) throw Error(shape);
    for (int r = 0; r < 3; ++r) sim.t[r] = t[r].get<double>();
    if (std::string(rkey) == "q_wxyz") {
      if (!rot.is_array() || rot.size() != 4) throw Error(shape);
      const Eigen::Quaterniond q(rot[0].get<double>(), rot[1].get<double>(), rot[2].get<double>(),
                                 rot[3].get<double>());
      if (!(std::abs(q.norm() - 1) < 1e-6)) throw Error("similarity: 'q_wxyz' is not a unit quaternion");
      R = q.normalized().toRotationMatrix();
    } else {
      if (!rot.is_array() || rot.size() != 3) throw Error(shape);
      for (int r = 0; r < 3; ++r) {
        if (!rot[r].is_array() || rot[r].size() != 3) throw Error(shape);
        for (int c = 0; c < 3; ++c) R(r, c) = rot[r][c].get<double>();
      }
    }
  } catch (const nlohmann::json::exception&) {
    throw Error(std::string("similarity: ") + shape);
  }
  if (!(sim.s > 0) || !std::isfinite(sim.s)) throw Error("similarity: scale must be a positive number");
  if (!R.allFinite() || !sim.t.allFinite()) throw Error("similarity: rotation and translation must be finite");
  if ((R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() > 1e-6 || R.determinant() < 0)
    throw Error("similarity: 'rotation' is not a rotation matrix (orthonormal with determinant +1)");
  sim.q = Eigen::Quaterniond(R).normalized();
  return sim;
}

core::Sim3 ReadSim3Json(const std::filesystem::path& path) {
  try {
    return Sim3FromJson(core::ReadJson(path));
  } catch (const Error& e) {
    throw Error(path.string() + ": " + e.what());
  }
}

}  // namespace fmv3d::align
