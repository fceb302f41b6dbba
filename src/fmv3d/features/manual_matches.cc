#include "fmv3d/features/manual_matches.h"

#include <fmt/format.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <set>

#include "fmv3d/core/error.h"
#include "fmv3d/features/sift.h"

namespace fmv3d::features {

void ManualMatchOptions::Check() const {
  if (!(max_epipolar_px > 0)) throw Error("match: --tie-max-epipolar-px must be > 0");
  if (!(keypoint_scale_px > 0)) throw Error("match: --tie-scale must be > 0");
  if (!(keypoint_ratio > 0 && keypoint_ratio <= 1)) throw Error("match: the keypoint ratio must be in (0, 1]");
}

std::filesystem::path ManualMatchesPath(const std::filesystem::path& matches_dir) {
  return matches_dir / "manual.json";
}

namespace {

std::map<std::string, uint32_t> FrameIndexByName(const io::FramesIndex& index) {
  std::map<std::string, uint32_t> by_name;
  for (size_t i = 0; i < index.frames.size(); ++i) by_name[index.frames[i].name] = static_cast<uint32_t>(i);
  return by_name;
}

uint32_t Lookup(const std::map<std::string, uint32_t>& by_name, const std::string& frame, const std::string& what) {
  const auto it = by_name.find(frame);
  if (it == by_name.end()) throw Error(what + ": frame \"" + frame + "\" is not in frames/frames.json");
  return it->second;
}

// Distance (pixels) of x2 from the epipolar line F·x1 (homogeneous pixels).
double LineDistance(const Eigen::Matrix3d& F, const Eigen::Vector2d& x1, const Eigen::Vector2d& x2) {
  const Eigen::Vector3d l = F * x1.homogeneous();
  const double n = l.head<2>().norm();
  return n > 0 ? std::abs(l.dot(x2.homogeneous())) / n : 0.0;
}

int DescriptorDistance2(const Descriptors& a, size_t i, const Descriptors& b, size_t j) {
  int d = 0;
  for (int k = 0; k < 128; ++k) {
    const int e = int(a(i, k)) - int(b(j, k));
    d += e * e;
  }
  return d;
}

VerifiedPair& PairFor(std::vector<VerifiedPair>* pairs, std::map<std::pair<uint32_t, uint32_t>, size_t>* where,
                      uint32_t a, uint32_t b) {
  const uint32_t id1 = std::min(a, b) + 1, id2 = std::max(a, b) + 1;
  auto it = where->find({id1, id2});
  if (it == where->end()) {
    VerifiedPair vp;  // rejected or never tried automatically: the tie points alone
    vp.image_id1 = id1;
    vp.image_id2 = id2;
    pairs->push_back(vp);
    it = where->emplace(std::make_pair(id1, id2), pairs->size() - 1).first;
  }
  return (*pairs)[it->second];
}

void AddMatch(VerifiedPair* vp, const ManualObservation& a, const ManualObservation& b) {
  FeatureMatch m =
      a.image + 1 == vp->image_id1 ? FeatureMatch{a.keypoint, b.keypoint} : FeatureMatch{b.keypoint, a.keypoint};
  if (std::find_if(vp->inliers.begin(), vp->inliers.end(),
                   [&](const FeatureMatch& x) { return x.idx1 == m.idx1 && x.idx2 == m.idx2; }) == vp->inliers.end())
    vp->inliers.push_back(m);
}

}  // namespace

void AppendToFeatureSet(const ManualMatches::Appended& ap, FeatureSet* fs, const std::string& what) {
  const size_t n0 = fs->keypoints.size();
  if (n0 != ap.first_index)
    throw Error(what + ": " + std::to_string(n0) + " automatic keypoints, not " + std::to_string(ap.first_index) +
                " (stale matches/manual.json: run `fmv3d match` again)");
  fs->keypoints.insert(fs->keypoints.end(), ap.keypoints.begin(), ap.keypoints.end());
  Descriptors d(n0 + ap.keypoints.size(), 128);
  if (n0) d.topRows(n0) = fs->descriptors.topRows(n0);
  d.bottomRows(ap.keypoints.size()) = ap.descriptors;
  fs->descriptors = std::move(d);
  if (fs->colors.size() == n0) fs->colors.insert(fs->colors.end(), ap.colors.begin(), ap.colors.end());
}

ManualMatches AppendManualKeypoints(const io::TiePoints& t, const io::FramesIndex& index,
                                    const std::map<uint32_t, cv::Mat>& images, std::vector<FeatureSet>* features,
                                    const ManualMatchOptions& options) {
  options.Check();
  if (features->size() != index.frames.size()) throw Error("manual matches: one feature set per frame expected");
  const auto by_name = FrameIndexByName(index);
  ManualMatches m;
  auto append = [&](const std::string& id, const io::ImagePoint& p, ManualTrackKind kind, ManualTrack* track) {
    const uint32_t i =
        Lookup(by_name, p.frame, (kind == ManualTrackKind::kTiePoint ? "tie point \"" : "keypoint \"") + id + "\"");
    auto [it, inserted] = m.appended.try_emplace(i);
    ManualMatches::Appended& ap = it->second;
    if (inserted) ap.first_index = static_cast<uint32_t>((*features)[i].keypoints.size());
    ap.ids.push_back(id);
    ap.keypoints.push_back(
        {static_cast<float>(p.x), static_cast<float>(p.y), static_cast<float>(options.keypoint_scale_px), 0.0f});
    track->observations.push_back({i, ap.first_index + static_cast<uint32_t>(ap.keypoints.size() - 1)});
  };
  for (const auto& tp : t.tie_points) {
    ManualTrack track{tp.id, ManualTrackKind::kTiePoint, {}};
    for (const auto& o : tp.observations) append(tp.id, o, ManualTrackKind::kTiePoint, &track);
    m.tracks.push_back(std::move(track));
  }
  for (const auto& kp : t.keypoints) {
    ManualTrack track{kp.id, ManualTrackKind::kKeypoint, {}};
    append(kp.id, kp.point, ManualTrackKind::kKeypoint, &track);
    m.tracks.push_back(std::move(track));
  }
  // Descriptors and colours from the images, then the feature sets grow.
  for (auto& [i, ap] : m.appended) {
    const auto img = images.find(i);
    const bool have = img != images.end() && !img->second.empty();
    ap.descriptors =
        have ? DescribeAt(img->second, ap.keypoints) : Descriptors(Descriptors::Zero(ap.keypoints.size(), 128));
    for (const auto& k : ap.keypoints) {
      Eigen::Matrix<uint8_t, 3, 1> rgb = Eigen::Matrix<uint8_t, 3, 1>::Zero();
      if (have) {
        const cv::Mat& im = img->second;
        const int c = std::clamp(static_cast<int>(k.x), 0, im.cols - 1),
                  r = std::clamp(static_cast<int>(k.y), 0, im.rows - 1);
        if (im.channels() == 3) {
          const cv::Vec3b& bgr = im.at<cv::Vec3b>(r, c);
          rgb = {bgr[2], bgr[1], bgr[0]};
        } else if (im.channels() == 1) {
          rgb.setConstant(im.at<uint8_t>(r, c));
        }
      }
      ap.colors.push_back(rgb);
    }
    AppendToFeatureSet(ap, &(*features)[i], index.frames[i].name);
  }
  return m;
}

void ApplyManualMatches(const io::TiePoints& t, const io::FramesIndex& index, const std::vector<FeatureSet>& features,
                        const ManualMatchOptions& options, ManualMatches* manual, std::vector<VerifiedPair>* pairs) {
  const auto by_name = FrameIndexByName(index);
  std::map<std::pair<uint32_t, uint32_t>, size_t> where;
  for (size_t k = 0; k < pairs->size(); ++k) where[{(*pairs)[k].image_id1, (*pairs)[k].image_id2}] = k;
  // Automatic F of a pair (before any manual pair is added), as image a → image b.
  auto automatic_f = [&](uint32_t a, uint32_t b, Eigen::Matrix3d* F) {
    const auto it = where.find({std::min(a, b) + 1, std::max(a, b) + 1});
    if (it == where.end() || (*pairs)[it->second].F.isZero()) return false;
    const Eigen::Matrix3d& f = (*pairs)[it->second].F;  // x2ᵀ F x1 = 0 with image_id1 → image_id2
    *F = a < b ? f : Eigen::Matrix3d(f.transpose());
    return true;
  };
  // Whether a pair's automatic F can judge a tie point: not when its matches lie on one plane (planar or rotation:
  // F is then free off that plane, and exact clicks on a roof were 18–25 px "off" it) nor when it rests on a few
  // inliers (a degraded frame's chance matches).
  auto f_determined = [&](uint32_t a, uint32_t b) {
    const auto it = where.find({std::min(a, b) + 1, std::max(a, b) + 1});
    if (it == where.end()) return false;
    const VerifiedPair& p = (*pairs)[it->second];
    return p.geometry != PairGeometry::kPlanarOrRotation &&
           p.num_inliers_F >= static_cast<uint32_t>(options.min_check_inliers);
  };
  auto pixel = [&](const ManualObservation& o) {
    const Keypoint& k = features[o.image].keypoints[o.keypoint];
    return Eigen::Vector2d(k.x, k.y);
  };

  // Single-frame keypoints: search along the epipolar line in the frames that verified a pair with theirs.
  for (auto& track : manual->tracks) {
    if (track.kind != ManualTrackKind::kKeypoint || track.observations.size() != 1) continue;
    const ManualObservation src = track.observations[0];
    const Eigen::Vector2d x = pixel(src);
    for (uint32_t j = 0; j < features.size(); ++j) {
      Eigen::Matrix3d F;
      if (j == src.image || !automatic_f(src.image, j, &F)) continue;
      const FeatureSet& other = features[j];
      const uint32_t n_auto = manual->appended.count(j) ? manual->appended.at(j).first_index
                                                        : static_cast<uint32_t>(other.keypoints.size());
      int best = -1, d1 = INT32_MAX, d2 = INT32_MAX;
      for (uint32_t k = 0; k < n_auto; ++k) {
        const Eigen::Vector2d y(other.keypoints[k].x, other.keypoints[k].y);
        if (LineDistance(F, x, y) > options.max_epipolar_px) continue;
        const int d = DescriptorDistance2(features[src.image].descriptors, src.keypoint, other.descriptors, k);
        if (d < d1) {
          d2 = d1;
          d1 = d;
          best = static_cast<int>(k);
        } else if (d < d2) {
          d2 = d;
        }
      }
      const double r = options.keypoint_ratio;
      if (best >= 0 && (d2 == INT32_MAX || double(d1) < r * r * double(d2))) {
        track.observations.push_back({j, static_cast<uint32_t>(best)});
        ++manual->keypoints_matched;
      }
    }
  }

  // Tie points (every pair of observations) and matched keypoints (each match with the clicked point).
  for (const auto& track : manual->tracks) {
    const auto& obs = track.observations;
    for (size_t a = 0; a < obs.size(); ++a)
      for (size_t b = a + 1; b < obs.size(); ++b) {
        if (track.kind == ManualTrackKind::kKeypoint && a != 0) break;
        Eigen::Matrix3d F;
        if (track.kind == ManualTrackKind::kTiePoint && automatic_f(obs[a].image, obs[b].image, &F) &&
            f_determined(obs[a].image, obs[b].image)) {
          const Eigen::Vector2d x1 = pixel(obs[a]), x2 = pixel(obs[b]);
          const double d = std::max(LineDistance(F, x1, x2), LineDistance(F.transpose(), x2, x1));
          if (d > options.max_epipolar_px)
            manual->disagreeing.push_back(
                {track.id, std::min(obs[a].image, obs[b].image), std::max(obs[a].image, obs[b].image), d});
        }
        AddMatch(&PairFor(pairs, &where, obs[a].image, obs[b].image), obs[a], obs[b]);
      }
  }

  // Deleted automatic matches.
  for (const auto& d : t.deleted_matches) {
    const uint32_t a = Lookup(by_name, d.frame1, "deleted match"), b = Lookup(by_name, d.frame2, "deleted match");
    const auto it = where.find({std::min(a, b) + 1, std::max(a, b) + 1});
    bool found = false;
    if (it != where.end()) {
      auto& inl = (*pairs)[it->second].inliers;
      const uint32_t i1 = a < b ? d.feature1 : d.feature2, i2 = a < b ? d.feature2 : d.feature1;
      const auto end =
          std::remove_if(inl.begin(), inl.end(), [&](const FeatureMatch& m) { return m.idx1 == i1 && m.idx2 == i2; });
      found = end != inl.end();
      inl.erase(end, inl.end());
    }
    ++(found ? manual->deleted : manual->deleted_not_found);
  }
  // A pair left with nothing is dropped.
  pairs->erase(std::remove_if(pairs->begin(), pairs->end(), [](const VerifiedPair& p) { return p.inliers.empty(); }),
               pairs->end());
}

nlohmann::json ManualMatches::ToJson(const io::FramesIndex& index) const {
  nlohmann::json frames = nlohmann::json::object();
  for (const auto& [i, ap] : appended) {
    nlohmann::json kps = nlohmann::json::array();
    for (size_t k = 0; k < ap.keypoints.size(); ++k) {
      std::vector<int> desc(128);
      for (int c = 0; c < 128; ++c) desc[c] = ap.descriptors(k, c);
      kps.push_back({{"id", ap.ids[k]},
                     {"x", ap.keypoints[k].x},
                     {"y", ap.keypoints[k].y},
                     {"scale", ap.keypoints[k].scale},
                     {"rgb", {ap.colors[k][0], ap.colors[k][1], ap.colors[k][2]}},
                     {"descriptor", desc}});
    }
    frames[index.frames.at(i).name] = {{"first_index", ap.first_index}, {"keypoints", kps}};
  }
  nlohmann::json tr = nlohmann::json::array();
  for (const auto& t : tracks) {
    nlohmann::json obs = nlohmann::json::array();
    for (const auto& o : t.observations)
      obs.push_back({{"frame", index.frames.at(o.image).name}, {"index", o.keypoint}});
    tr.push_back({{"id", t.id},
                  {"kind", t.kind == ManualTrackKind::kTiePoint ? "tie_point" : "keypoint"},
                  {"observations", obs}});
  }
  nlohmann::json dis = nlohmann::json::array();
  for (const auto& d : disagreeing)
    dis.push_back({{"id", d.id},
                   {"frame1", index.frames.at(d.image1).name},
                   {"frame2", index.frames.at(d.image2).name},
                   {"epipolar_px", d.epipolar_px}});
  return {{"format", "fmv3d-manual-matches"},
          {"version", 1},
          {"frames", frames},
          {"tracks", tr},
          {"disagreeing", dis},
          {"deleted", deleted},
          {"deleted_not_found", deleted_not_found},
          {"keypoints_matched", keypoints_matched}};
}

ManualMatches ManualMatches::FromJson(const nlohmann::json& j, const io::FramesIndex& index) {
  const auto by_name = FrameIndexByName(index);
  ManualMatches m;
  try {
    if (j.at("format").get<std::string>() != "fmv3d-manual-matches" || j.at("version").get<int>() != 1)
      throw Error("not an fmv3d-manual-matches version 1 file");
    for (const auto& [name, f] : j.at("frames").items()) {
      Appended ap;
      ap.first_index = f.at("first_index").get<uint32_t>();
      const auto& kps = f.at("keypoints");
      ap.descriptors.resize(kps.size(), 128);
      for (size_t k = 0; k < kps.size(); ++k) {
        const auto& e = kps[k];
        ap.ids.push_back(e.at("id").get<std::string>());
        ap.keypoints.push_back({e.at("x").get<float>(), e.at("y").get<float>(), e.at("scale").get<float>(), 0.0f});
        const auto rgb = e.at("rgb").get<std::vector<int>>();
        const auto desc = e.at("descriptor").get<std::vector<int>>();
        if (rgb.size() != 3 || desc.size() != 128) throw Error("keypoint " + ap.ids.back() + ": bad rgb or descriptor");
        ap.colors.push_back({uint8_t(rgb[0]), uint8_t(rgb[1]), uint8_t(rgb[2])});
        for (int c = 0; c < 128; ++c) ap.descriptors(k, c) = static_cast<uint8_t>(std::clamp(desc[c], 0, 255));
      }
      m.appended[Lookup(by_name, name, "manual.json")] = std::move(ap);
    }
    for (const auto& e : j.at("tracks")) {
      ManualTrack t;
      t.id = e.at("id").get<std::string>();
      t.kind = e.at("kind").get<std::string>() == "keypoint" ? ManualTrackKind::kKeypoint : ManualTrackKind::kTiePoint;
      for (const auto& o : e.at("observations"))
        t.observations.push_back(
            {Lookup(by_name, o.at("frame").get<std::string>(), "manual.json"), o.at("index").get<uint32_t>()});
      m.tracks.push_back(std::move(t));
    }
    m.deleted = j.value("deleted", size_t{0});
  } catch (const nlohmann::json::exception& e) {
    throw Error(std::string("manual.json: malformed (") + e.what() + ") — run `fmv3d match` again");
  }
  return m;
}

}  // namespace fmv3d::features
