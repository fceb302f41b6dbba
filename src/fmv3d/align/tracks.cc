#include "fmv3d/align/tracks.h"

#include <spdlog/spdlog.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <map>
#include <memory>
#include <opencv2/calib3d.hpp>
#include <set>

#include "fmv3d/align/sim3_json.h"
#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/logging.h"
#include "fmv3d/core/stats.h"
#include "fmv3d/core/workspace.h"
#include "fmv3d/features/feature_io.h"
#include "fmv3d/features/pairs.h"
#include "fmv3d/geometry/similarity.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/mvs/dense_stage.h"

namespace fmv3d::align {
namespace {

namespace fs = std::filesystem;

// The keypoints of one registered image that have a 3D point: their descriptors, undistorted rays and ids.
struct ImageFeatures {
  uint32_t image_id = 0;
  features::Descriptors descriptors;
  std::vector<Eigen::Vector2d> rays;  // normalised camera coordinates (x/z, y/z), distortion removed
  std::vector<uint64_t> points;       // 3D point id per row
  double focal = 1;                   // pixels, for the verification threshold
};

std::vector<ImageFeatures> LoadFeatures(const Track& t) {
  std::vector<ImageFeatures> out;
  const fs::path dir = core::Workspace(t.workspace).features_dir();
  for (const auto& [id, image] : t.sparse.images) {
    const fs::path path = features::FeaturePath(dir, image.name);
    if (!fs::exists(path))
      throw Error(t.name + ": no features for " + image.name + " (" + path.string() + ") — run `fmv3d features` first");
    const features::FeatureSet fset = features::ReadFeatures(path);
    if (fset.keypoints.size() != image.points2d.size())
      throw Error(path.string() + ": " + std::to_string(fset.keypoints.size()) +
                  " keypoints, but the sparse model has " + std::to_string(image.points2d.size()) + " for " +
                  image.name + " (features newer than the model?)");
    const core::Camera& cam = t.sparse.cameras.at(image.camera_id);
    ImageFeatures f;
    f.image_id = id;
    f.focal = cam.f;
    std::vector<int> rows;
    for (size_t k = 0; k < image.point3d_ids.size(); ++k)
      if (image.point3d_ids[k] != core::kNoPoint3D && t.sparse.points.count(image.point3d_ids[k]))
        rows.push_back(int(k));
    f.descriptors.resize(rows.size(), 128);
    for (size_t r = 0; r < rows.size(); ++r) {
      f.descriptors.row(r) = fset.descriptors.row(rows[r]);
      f.rays.push_back(cam.Unproject(image.points2d[rows[r]]).head<2>());
      f.points.push_back(static_cast<uint64_t>(image.point3d_ids[rows[r]]));
    }
    out.push_back(std::move(f));
  }
  return out;
}

std::vector<Eigen::Vector3d> Positions(const core::Reconstruction& r) {
  std::vector<Eigen::Vector3d> p;
  p.reserve(r.points.size());
  for (const auto& [id, pt] : r.points) p.push_back(pt.xyz);
  return p;
}

// The moving track's points (dense if both have dense clouds, else sparse) that land within 3 median
// spacings of a reference point.
double OverlapFraction(const Track& ref, const Track& mov, const core::Sim3& sim) {
  const bool dense = !ref.dense.empty() && !mov.dense.empty();
  const std::vector<Eigen::Vector3d> rp = dense ? ref.dense.positions : Positions(ref.sparse);
  const std::vector<Eigen::Vector3d> mp = dense ? mov.dense.positions : Positions(mov.sparse);
  if (rp.size() < 2 || mp.empty()) return 0;
  const PointIndex index(rp);
  const double r = 3 * MedianSpacing(rp, index);
  const auto pick = EvenSubsample(mp.size(), 50000);
  size_t near = 0;
  for (int i : pick) {
    double d2 = 0;
    if (index.Nearest(sim.Apply(mp[i]), &d2) >= 0 && d2 <= r * r) ++near;
  }
  return double(near) / pick.size();
}

struct FeatureCache {
  std::vector<std::unique_ptr<std::vector<ImageFeatures>>> tracks;
  const std::vector<ImageFeatures>& Get(const std::vector<Track>& all, size_t i) {
    if (tracks.size() < all.size()) tracks.resize(all.size());
    if (!tracks[i]) tracks[i] = std::make_unique<std::vector<ImageFeatures>>(LoadFeatures(all[i]));
    return *tracks[i];
  }
};

std::string NoOverlap(const Track& a, const Track& b) {
  return "no overlap found between " + a.name + " and " + b.name;
}

// Candidate image pairs (index into fa, index into fb): every pair when few, else each image's most similar
// images of the other track by global descriptor.
std::vector<std::pair<size_t, size_t>> CandidatePairs(const std::vector<ImageFeatures>& fa,
                                                      const std::vector<ImageFeatures>& fb,
                                                      const TrackAlignOptions& o) {
  std::set<std::pair<size_t, size_t>> cand;
  if (fa.size() * fb.size() <= static_cast<size_t>(o.exhaustive_max_pairs)) {
    for (size_t i = 0; i < fa.size(); ++i)
      for (size_t j = 0; j < fb.size(); ++j) cand.insert({i, j});
    return {cand.begin(), cand.end()};
  }
  std::vector<const features::Descriptors*> all;
  all.reserve(fa.size() + fb.size());
  for (const auto& f : fa) all.push_back(&f.descriptors);
  for (const auto& f : fb) all.push_back(&f.descriptors);
  features::PairOptions po;
  po.seed = o.seed;
  const auto g = features::GlobalDescriptors(all, po);
  auto top = [&](size_t self, size_t begin, size_t end) {
    std::vector<std::pair<float, size_t>> sims;
    for (size_t k = begin; k < end; ++k) {
      float dot = 0;
      for (size_t d = 0; d < g[self].size(); ++d) dot += g[self][d] * g[k][d];
      sims.push_back({-dot, k});
    }
    const size_t n = std::min<size_t>(o.candidates_per_image, sims.size());
    std::partial_sort(sims.begin(), sims.begin() + n, sims.end());
    sims.resize(n);
    return sims;
  };
  for (size_t i = 0; i < fa.size(); ++i)
    for (const auto& [s, k] : top(i, fa.size(), all.size())) cand.insert({i, k - fa.size()});
  for (size_t j = 0; j < fb.size(); ++j)
    for (const auto& [s, k] : top(fa.size() + j, 0, fa.size())) cand.insert({k, j});
  return {cand.begin(), cand.end()};
}

// Matches and verifies (essential matrix, RANSAC) each candidate pair in parallel; per pair, the 3D point ids
// (reference, moving) of its verified matches, empty when it did not verify.
std::vector<std::vector<std::pair<uint64_t, uint64_t>>> CrossMatch(const std::vector<ImageFeatures>& fa,
                                                                   const std::vector<ImageFeatures>& fb,
                                                                   const std::vector<std::pair<size_t, size_t>>& pairs,
                                                                   const TrackAlignOptions& o,
                                                                   const std::string& label) {
  // Descriptors' search structures are built once per image.
  std::vector<std::unique_ptr<features::ImageDescriptors>> da, db;
  for (size_t i = 0; i < fa.size(); ++i)
    da.push_back(std::make_unique<features::ImageDescriptors>(fa[i].descriptors, uint32_t(i + 1)));
  for (size_t j = 0; j < fb.size(); ++j)
    db.push_back(std::make_unique<features::ImageDescriptors>(fb[j].descriptors, uint32_t(100000 + j)));
  std::vector<std::vector<std::pair<uint64_t, uint64_t>>> found(pairs.size());
  core::Progress progress("cross-match " + label, pairs.size());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, pairs.size(), 1), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t p = r.begin(); p < r.end(); ++p) {
      const auto& A = fa[pairs[p].first];
      const auto& B = fb[pairs[p].second];
      progress.Add();
      if (A.points.size() < 8 || B.points.size() < 8) continue;
      const auto matches = features::MatchDescriptors(*da[pairs[p].first], *db[pairs[p].second], o.match);
      if (static_cast<int>(matches.size()) < o.min_pair_inliers) continue;
      std::vector<cv::Point2d> x1, x2;
      for (const auto& m : matches) {
        x1.emplace_back(A.rays[m.idx1].x(), A.rays[m.idx1].y());
        x2.emplace_back(B.rays[m.idx2].x(), B.rays[m.idx2].y());
      }
      cv::Mat mask;
      const double thr = o.verify_max_error_px / std::max(std::min(A.focal, B.focal), 1.0);
      const cv::Mat E = cv::findEssentialMat(x1, x2, cv::Mat::eye(3, 3, CV_64F), cv::RANSAC, 0.999, thr, mask);
      if (E.empty() || mask.empty()) continue;
      std::vector<std::pair<uint64_t, uint64_t>> keep;
      for (size_t k = 0; k < matches.size(); ++k)
        if (mask.at<uint8_t>(int(k))) keep.push_back({A.points[matches[k].idx1], B.points[matches[k].idx2]});
      if (static_cast<int>(keep.size()) >= o.min_pair_inliers) found[p] = std::move(keep);
    }
  });
  progress.Finish();
  return found;
}

// Robust refit of the similarity src → dst: IRLS with Huber weights, the inlier set (mask) re-chosen each round
// at 3 robust sigmas of the residuals, never beyond max_error.
core::Sim3 RefitSimilarityIrls(const std::vector<Eigen::Vector3d>& src, const std::vector<Eigen::Vector3d>& dst,
                               core::Sim3 sim, double max_error, double scale, int min_inliers,
                               std::vector<char>& mask) {
  for (int round = 0; round < 6; ++round) {
    std::vector<double> r(src.size()), rin;
    for (size_t i = 0; i < src.size(); ++i) {
      r[i] = (sim.Apply(src[i]) - dst[i]).norm();
      if (mask[i]) rin.push_back(r[i]);
    }
    const double sigma = std::max(core::RobustSigma(rin), 1e-12 * scale);
    std::vector<Eigen::Vector3d> a, b;
    std::vector<double> w;
    for (size_t i = 0; i < src.size(); ++i) {
      mask[i] = r[i] <= std::min(3 * sigma, max_error);
      if (!mask[i]) continue;
      a.push_back(src[i]);
      b.push_back(dst[i]);
      w.push_back(r[i] <= 1.5 * sigma ? 1.0 : 1.5 * sigma / r[i]);
    }
    core::Sim3 refit;
    if (static_cast<int>(a.size()) < min_inliers || !geometry::EstimateSimilarity(a, b, w, true, &refit)) break;
    sim = refit;
  }
  return sim;
}

// The fine step: scaled ICP between the dense clouds, started at the similarity from correspondences.
void RefineByDenseIcp(const Track& ref, const Track& mov, const TrackAlignOptions& o, core::Sim3& sim,
                      PairAlignment& res) {
  IcpOptions io = o.icp_options;
  const double overlap = OverlapFraction(ref, mov, sim);
  io.trim_fraction = std::clamp(overlap, 0.3, io.trim_fraction);
  const IcpTarget target(ref.dense, io.normal_neighbours);
  const IcpResult icp = ScaledIcp(mov.dense, target, sim, io);
  spdlog::info("align {} ← {}: ICP on dense clouds, RMS {:.4g} → {:.4g}, {} iterations", ref.name, mov.name,
               icp.initial_rmse, icp.rmse, icp.iterations);
  sim = icp.transform;
  res.rms_before = icp.initial_rmse;
  res.rms_after = icp.rmse;
  res.fine = "icp-dense";
}

PairAlignment AlignPair(const std::vector<Track>& tracks, size_t ri, size_t mi, const TrackAlignOptions& o,
                        FeatureCache& cache) {
  const Track& ref = tracks[ri];
  const Track& mov = tracks[mi];
  const auto& fa = cache.Get(tracks, ri);
  const auto& fb = cache.Get(tracks, mi);
  PairAlignment res;
  res.reference = ri;
  res.moving = mi;
  const std::vector<std::pair<size_t, size_t>> pairs = CandidatePairs(fa, fb, o);
  res.image_pairs_tried = pairs.size();
  const auto found = CrossMatch(fa, fb, pairs, o, ref.name + " / " + mov.name);

  // 3. Distinct 3D–3D pairs.
  std::set<std::pair<uint64_t, uint64_t>> links;
  for (const auto& f : found) {
    res.image_pairs_verified += !f.empty();
    links.insert(f.begin(), f.end());
  }
  res.correspondences = links.size();
  std::vector<Eigen::Vector3d> src, dst;
  const std::vector<std::pair<uint64_t, uint64_t>> link_list(links.begin(), links.end());
  for (const auto& [a, b] : link_list) {
    dst.push_back(ref.sparse.points.at(a).xyz);
    src.push_back(mov.sparse.points.at(b).xyz);
  }
  spdlog::info("align {} ← {}: {} image pairs verified of {}, {} 3D–3D correspondences", ref.name, mov.name,
               res.image_pairs_verified, res.image_pairs_tried, res.correspondences);
  if (static_cast<int>(src.size()) < o.min_inliers) throw NoOverlapError(NoOverlap(ref, mov));
  geometry::SimilarityRansacOptions ro;
  ro.max_error = o.ransac_max_error * ref.radius;
  ro.max_iterations = 5000;
  ro.seed = o.seed;
  core::Sim3 sim;
  std::vector<char> mask;
  const int inliers = geometry::EstimateSimilarityRansac(src, dst, ro, &sim, &mask);
  if (inliers < o.min_inliers)
    throw NoOverlapError(NoOverlap(ref, mov) + " (" + std::to_string(inliers) + " consistent 3D correspondences, " +
                         std::to_string(o.min_inliers) + " needed)");

  const core::Sim3 coarse = sim;
  sim = RefitSimilarityIrls(src, dst, sim, ro.max_error, ref.radius, o.min_inliers, mask);
  auto inlier_rms = [&](const core::Sim3& s) {
    double sum = 0;
    size_t n = 0;
    for (size_t i = 0; i < src.size(); ++i)
      if (mask[i]) {
        sum += (s.Apply(src[i]) - dst[i]).squaredNorm();
        ++n;
      }
    return n ? std::sqrt(sum / n) : 0.0;
  };
  res.inliers = std::count(mask.begin(), mask.end(), 1);
  for (size_t i = 0; i < link_list.size(); ++i)
    if (mask[i]) res.links.push_back(link_list[i]);
  res.rms_before = inlier_rms(coarse);
  res.rms_after = inlier_rms(sim);
  res.fine = "correspondences";

  if (o.icp && !ref.dense.empty() && !mov.dense.empty()) RefineByDenseIcp(ref, mov, o, sim, res);
  res.sim = sim;
  res.overlap_fraction = OverlapFraction(ref, mov, sim);
  spdlog::info("align {} ← {}: {} inliers, scale {:.6g}, overlap {:.0f}%, RMS {:.4g} ({:.4f}% of the scene radius)",
               ref.name, mov.name, res.inliers, sim.s, 100 * res.overlap_fraction, res.rms_after,
               100 * res.rms_after / ref.radius);
  return res;
}

}  // namespace

Track LoadTrack(const fs::path& workspace) {
  Track t;
  t.workspace = workspace;
  t.name = fs::path(workspace).lexically_normal().filename().string();
  if (t.name.empty() || t.name == ".")
    t.name = fs::absolute(workspace).lexically_normal().parent_path().filename().string();
  const core::Workspace ws(workspace);
  const fs::path sparse = ws.sparse_dir();
  if (!fs::exists(sparse / "images.txt"))
    throw Error(workspace.string() + ": no sparse/images.txt — run `fmv3d sparse` first");
  t.sparse = io::ReadColmapText(sparse);
  if (t.sparse.images.size() < 3 || t.sparse.points.size() < 3)
    throw Error(workspace.string() + ": the sparse model is too small to align (" +
                std::to_string(t.sparse.images.size()) + " images, " + std::to_string(t.sparse.points.size()) +
                " points)");
  const fs::path fused = ws.dense_dir() / "fused.ply";
  if (fs::exists(fused)) t.dense = io::ReadPointCloudPly(fused);
  const fs::path dense_report = ws.report_dir() / "dense.json";
  const nlohmann::json r = fs::exists(dense_report) ? core::ReadJson(dense_report) : nlohmann::json();
  if (r.is_object()) {
    const mvs::DenseStageOptions defaults;
    DenseSettings& d = t.dense_settings.emplace();
    d.max_size = r.value("max_size", defaults.max_size);
    d.max_sources = r.value("max_sources", defaults.max_sources);
    d.geometric_pass = r.value("geometric_pass", defaults.geometric);
    d.reference_coverage = r.value("reference_coverage", 0);
  }
  t.radius = RmsRadius(Positions(t.sparse));
  return t;
}

void TrackAlignOptions::Check() const {
  if (exhaustive_max_pairs < 0) throw Error("align: exhaustive_max_pairs must be >= 0");
  if (candidates_per_image < 1) throw Error("align: candidates_per_image must be >= 1");
  if (!(verify_max_error_px > 0)) throw Error("align: verify_max_error_px must be > 0");
  if (min_pair_inliers < 8) throw Error("align: min_pair_inliers must be >= 8");
  if (min_inliers < 3) throw Error("align: min_inliers must be >= 3");
  if (!(ransac_max_error > 0)) throw Error("align: ransac_max_error must be > 0");
  match.Check();
  icp_options.Check();
}

nlohmann::json PairAlignment::ToJson(const std::vector<Track>& tracks) const {
  return {{"reference", tracks[reference].name},
          {"moving", tracks[moving].name},
          {"similarity", Sim3ToJson(sim)},
          {"image_pairs_tried", image_pairs_tried},
          {"image_pairs_verified", image_pairs_verified},
          {"correspondences_3d", correspondences},
          {"inliers_3d", inliers},
          {"overlap_fraction", overlap_fraction},
          {"fine", fine},
          {"residual_rms_before", rms_before},
          {"residual_rms_after", rms_after},
          {"residual_rms_after_percent_of_radius", 100 * rms_after / std::max(tracks[reference].radius, 1e-300)}};
}

PairAlignment AlignTrackPair(const std::vector<Track>& tracks, size_t reference, size_t moving,
                             const TrackAlignOptions& options) {
  options.Check();
  if (reference >= tracks.size() || moving >= tracks.size() || reference == moving)
    throw Error("align: bad track indices");
  FeatureCache cache;
  return AlignPair(tracks, reference, moving, options, cache);
}

MultiTrackAlignment AlignTracks(const std::vector<Track>& tracks, const TrackAlignOptions& options) {
  options.Check();
  const size_t n = tracks.size();
  if (n < 2) throw Error("align: need at least two workspaces");
  MultiTrackAlignment out;
  for (size_t i = 1; i < n; ++i) {
    const auto key = [&](size_t k) {
      return std::make_pair(tracks[k].sparse.images.size(), tracks[k].sparse.points.size());
    };
    if (key(i) > key(out.reference)) out.reference = i;
  }
  // Every pair, each aligned towards the larger of the two (the one nearer the reference, by size).
  FeatureCache cache;
  std::string last_error;
  for (size_t i = 0; i < n; ++i)
    for (size_t j = i + 1; j < n; ++j) {
      const bool j_ref = j == out.reference;
      try {
        out.pairs.push_back(j_ref ? AlignPair(tracks, j, i, options, cache) : AlignPair(tracks, i, j, options, cache));
      } catch (const NoOverlapError& e) {
        spdlog::warn("align: {}", e.what());
        last_error = e.what();
      }
    }
  // Maximum spanning tree from the reference (Prim), weight = inlier count.
  std::vector<char> in_tree(n, 0);
  in_tree[out.reference] = 1;
  out.to_reference.assign(n, core::Sim3());
  for (size_t added = 1; added < n; ++added) {
    const PairAlignment* best = nullptr;
    for (const auto& p : out.pairs)
      if (in_tree[p.reference] != in_tree[p.moving] && (!best || p.inliers > best->inliers)) best = &p;
    if (!best) {
      if (n == 2) throw NoOverlapError(last_error.empty() ? NoOverlap(tracks[0], tracks[1]) : last_error);
      for (size_t k = 0; k < n; ++k)
        if (!in_tree[k]) throw NoOverlapError("no overlap found between " + tracks[k].name + " and any other track");
    }
    // Edge b→a (b's frame into a's): T_b = T_a ∘ sim, or through the inverse when the tree grows the other way.
    if (in_tree[best->reference]) {
      out.to_reference[best->moving] = ComposeSim3(out.to_reference[best->reference], best->sim);
      in_tree[best->moving] = 1;
    } else {
      out.to_reference[best->reference] = ComposeSim3(out.to_reference[best->moving], best->sim.Inverse());
      in_tree[best->reference] = 1;
    }
    out.tree.push_back(*best);
  }
  return out;
}

}  // namespace fmv3d::align
