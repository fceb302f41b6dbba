#include "fmv3d/pipeline/manual_check.h"

#include <set>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/features/feature_io.h"
#include "fmv3d/geo/gcp_list.h"
#include "fmv3d/io/frames_index.h"
#include "fmv3d/io/tiepoints.h"

namespace fmv3d::pipeline {
namespace fs = std::filesystem;

nlohmann::json ManualCheck::ToJson() const {
  auto file = [](const ManualFileCheck& f) {
    return nlohmann::json{
        {"path", f.path.string()}, {"present", f.present}, {"valid", f.valid()}, {"errors", f.errors}};
  };
  nlohmann::json t = file(tiepoints), g = file(gcp);
  t["tie_points"] = tie_points;
  t["keypoints"] = keypoints;
  t["deleted_matches"] = deleted_matches;
  g["crs"] = crs;
  g["points"] = gcp_points;
  g["check_points"] = check_points;
  g["observations"] = gcp_observations;
  return {{"tiepoints", t}, {"gcp", g}, {"ok", ok()}};
}

ManualCheck CheckManualInputs(const core::Workspace& ws, const std::optional<fs::path>& tiepoints,
                              const std::optional<fs::path>& gcp_list) {
  ws.Require(ws.frames_json(), "frames");
  const io::FramesIndex index = io::ReadFramesIndex(ws.frames_json());
  io::FrameTable frames = io::FrameTableOf(index);
  ManualCheck out;
  out.tiepoints.path = tiepoints.value_or(ws.manual_dir() / "tiepoints.json");
  out.gcp.path = gcp_list.value_or(ws.manual_dir() / "gcp_list.txt");

  out.tiepoints.present = fs::exists(out.tiepoints.path);
  if (out.tiepoints.present) {
    try {
      auto& errors = out.tiepoints.errors;
      const io::TiePoints t = io::ParseTiePoints(core::ReadTextFile(out.tiepoints.path), &errors);
      {
        std::set<std::string> named;
        for (const auto& d : t.deleted_matches) named.insert({d.frame1, d.frame2});
        for (const auto& name : named) {
          auto it = frames.find(name);
          const fs::path fp = features::FeaturePath(ws.features_dir(), name);
          if (it != frames.end() && fs::exists(fp))
            it->second.num_keypoints = features::ReadFeatures(fp).keypoints.size();
        }
        io::CheckTiePoints(t, frames, &errors);
        out.tie_points = t.tie_points.size();
        out.keypoints = t.keypoints.size();
        out.deleted_matches = t.deleted_matches.size();
      }
      const std::string what = out.tiepoints.path.filename().string() + ": ";
      for (auto& e : errors) e = what + e;
    } catch (const Error& e) {
      out.tiepoints.errors.push_back(e.what());
    }
  }
  out.gcp.present = fs::exists(out.gcp.path);
  if (out.gcp.present) {
    try {
      auto& errors = out.gcp.errors;
      const std::string what = out.gcp.path.filename().string();
      const geo::GcpList list = geo::ParseGcpList(core::ReadTextFile(out.gcp.path), &errors, what);
      {
        geo::CheckGcpList(list, frames, &errors, what);
        out.crs = list.crs;
        for (const auto& p : geo::GroupGcps(list)) {
          ++out.gcp_points;
          out.check_points += p.check;
          out.gcp_observations += p.observations.size();
        }
      }
    } catch (const Error& e) {
      out.gcp.errors.push_back(e.what());
    }
  }
  return out;
}

}  // namespace fmv3d::pipeline
