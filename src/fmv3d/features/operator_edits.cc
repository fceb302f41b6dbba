#include "fmv3d/features/operator_edits.h"

#include <spdlog/spdlog.h>

#include <opencv2/imgcodecs.hpp>
#include <string>

#include "fmv3d/core/files.h"
#include "fmv3d/features/manual_matches.h"
#include "fmv3d/io/tiepoints.h"

namespace fmv3d::features {
namespace fs = std::filesystem;

namespace {

// The frames whose pairs tie points, keypoints and deleted matches change (ApplyManualMatches reads and edits only
// pairs with one of these frames).
std::set<uint32_t> NamedFrames(const io::TiePoints& t, const io::FramesIndex& index) {
  std::set<std::string> names;
  for (const auto& tp : t.tie_points)
    for (const auto& o : tp.observations) names.insert(o.frame);
  for (const auto& kp : t.keypoints) names.insert(kp.point.frame);
  for (const auto& d : t.deleted_matches) {
    names.insert(d.frame1);
    names.insert(d.frame2);
  }
  std::set<uint32_t> frames;
  for (size_t i = 0; i < index.frames.size(); ++i)
    if (names.count(index.frames[i].name)) frames.insert(static_cast<uint32_t>(i));
  return frames;
}

// ApplyManualMatches on the verified pairs it touches, read from automatic.bin.
void EditTouchedPairs(const io::TiePoints& tie_points, const io::FramesIndex& index,
                      const std::vector<FeatureSet>& features, const MatchStageOptions& options,
                      MatchFileReader* automatic, const std::vector<size_t>& verified, ManualMatches* manual,
                      OperatorEdits* edits) {
  std::vector<VerifiedPair> touched;
  for (size_t k : verified)
    if (edits->Touches(automatic->ids(k))) touched.push_back(automatic->Read(k));
  std::set<std::pair<uint32_t, uint32_t>> before;
  for (const auto& vp : touched) before.emplace(vp.image_id1, vp.image_id2);
  ApplyManualMatches(tie_points, index, features, options.manual, manual, &touched);
  for (auto& vp : touched) {
    const std::pair<uint32_t, uint32_t> ids{vp.image_id1, vp.image_id2};
    if (before.count(ids))
      edits->edited.emplace(ids, std::move(vp));
    else
      edits->added.push_back(std::move(vp));
  }
}

}  // namespace

nlohmann::json ApplyOperatorInput(const core::Workspace& ws, const io::FramesIndex& index, const DescriptorLoader& load,
                                  const MatchStageOptions& options, std::vector<FeatureSet>* features,
                                  MatchFileReader* automatic, const std::vector<size_t>& verified,
                                  OperatorEdits* edits) {
  const fs::path tiepoints_path = options.tiepoints_file.value_or(ws.manual_dir() / "tiepoints.json");
  const fs::path manual_path = ManualMatchesPath(ws.matches_dir());
  if (!options.tiepoints_file && !(options.use_tiepoints && fs::exists(tiepoints_path))) {
    if (fs::exists(manual_path)) fs::remove(manual_path);
    return {{"used", false}};
  }
  const size_t n = index.frames.size();
  io::FrameTable table = io::FrameTableOf(index);
  for (size_t i = 0; i < n; ++i) table[index.frames[i].name].num_keypoints = (*features)[i].keypoints.size();
  const io::TiePoints tie_points = io::ReadTiePoints(tiepoints_path, &table);
  std::set<std::string> clicked;
  for (const auto& tp : tie_points.tie_points)
    for (const auto& o : tp.observations) clicked.insert(o.frame);
  for (const auto& kp : tie_points.keypoints) clicked.insert(kp.point.frame);
  std::map<uint32_t, cv::Mat> images;
  for (size_t i = 0; i < n; ++i)
    if (clicked.count(index.frames[i].name)) {
      images[i] = cv::imread((ws.frames_dir() / index.frames[i].name).string(), cv::IMREAD_COLOR);
      if (images[i].empty())
        spdlog::warn("match: cannot read frames/{}: its tie points get no descriptor", index.frames[i].name);
    }
  // Descriptors where the operator's points need them: the clicked frames and the frames they verified a pair
  // with (a keypoint clicked in one frame is searched for along its epipolar lines there).
  std::set<uint32_t> involved;
  for (size_t i = 0; i < n; ++i)
    if (clicked.count(index.frames[i].name)) involved.insert(static_cast<uint32_t>(i));
  for (size_t k : verified) {
    const auto [id1, id2] = automatic->ids(k);
    if (involved.count(id1 - 1) || involved.count(id2 - 1)) {
      involved.insert(id1 - 1);
      involved.insert(id2 - 1);
    }
  }
  for (uint32_t i : involved)
    if ((*features)[i].descriptors.rows() != static_cast<Eigen::Index>((*features)[i].keypoints.size()))
      (*features)[i].descriptors = load(i);
  ManualMatches manual = AppendManualKeypoints(tie_points, index, images, features, options.manual);
  edits->used = true;
  edits->frames = NamedFrames(tie_points, index);
  EditTouchedPairs(tie_points, index, *features, options, automatic, verified, &manual, edits);
  const nlohmann::json manual_json = manual.ToJson(index);
  core::WriteJson(manual_path, manual_json);
  for (const auto& d : manual.disagreeing)
    spdlog::warn("match: tie point \"{}\" is {:.1f} px from the epipolar line of {} / {} (kept)", d.id, d.epipolar_px,
                 index.frames[d.image1].name, index.frames[d.image2].name);
  spdlog::info("match: {} tie points, {} keypoints ({} matches found), {} deleted matches removed",
               tie_points.tie_points.size(), tie_points.keypoints.size(), manual.keypoints_matched, manual.deleted);
  return {{"used", true},
          {"file", tiepoints_path.string()},
          {"tie_points", tie_points.tie_points.size()},
          {"keypoints", tie_points.keypoints.size()},
          {"keypoint_matches_found", manual.keypoints_matched},
          {"deleted_matches_removed", manual.deleted},
          {"deleted_matches_not_found", manual.deleted_not_found},
          {"pairs_added", 0},
          {"max_epipolar_px", options.manual.max_epipolar_px},
          {"disagreeing", manual_json["disagreeing"]}};
}

size_t WriteFinalMatches(MatchFileReader* automatic, const std::vector<size_t>& verified, const OperatorEdits& edits,
                         const fs::path& path) {
  MatchFileWriter out(path);
  for (size_t k : verified) {
    const auto ids = automatic->ids(k);
    if (edits.used && edits.Touches(ids)) {
      const auto it = edits.edited.find(ids);
      if (it != edits.edited.end()) out.Add(it->second);
      continue;
    }
    const VerifiedPair vp = automatic->Read(k);
    if (!(edits.used && vp.inliers.empty())) out.Add(vp);
  }
  for (const auto& vp : edits.added) out.Add(vp);
  out.Finish();
  return out.count();
}

}  // namespace fmv3d::features
