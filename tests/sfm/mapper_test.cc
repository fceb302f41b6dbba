// End-to-end incremental mapper on synthetic correspondences with exact ground truth.
#include <gtest/gtest.h>
#include <spdlog/spdlog.h>

#include <Eigen/Geometry>
#include <map>
#include <random>

#include "fmv3d/core/error.h"
#include "fmv3d/sfm/evaluation.h"
#include "fmv3d/sfm/incremental_mapper.h"
#include "fmv3d/sfm/mapper_report.h"
#include "fmv3d/sfm/synthetic_correspondences.h"

namespace fmv3d::sfm {
namespace {

struct Outcome {
  MapperResult result;
  SparseEvaluation eval;
};

Outcome RunAndEvaluate(const SyntheticScene& scene, const MapperOptions& options = {}) {
  Outcome out;
  out.result = RunIncrementalMapper(scene.input, options);
  if (!out.result.models.empty()) out.eval = EvaluateSparse(out.result.models[0], scene.truth);
  const auto& rec = out.result.models.empty() ? core::Reconstruction() : out.result.models[0];
  std::printf("%s\n", ToJson(out.result.stats).dump().c_str());
  if (!rec.cameras.empty()) {
    const auto& c = rec.cameras.begin()->second;
    std::printf(
        "registered %zu/%zu, points %zu, track %.2f, reproj %.3f px, centre %.4f%%, rot %.4f deg, "
        "focal %.4f%% (f %.2f k1 %.4f k2 %.4f pp %.1f %.1f)\n",
        rec.images.size(), scene.input.images.size(), rec.points.size(), rec.MeanTrackLength(),
        rec.MeanReprojectionError(), 100 * out.eval.centre_rmse_fraction, out.eval.median_rotation_error_deg,
        100 * out.eval.focal_relative_error, c.f, c.k1, c.k2, c.u0, c.v0);
  }
  return out;
}

TEST(IncrementalMapper, OrbitSelfCalibratesFocalAndDistortion) {
  SyntheticSceneOptions so;  // 40 cameras, 2000 points, 0.5 px noise, 10% outliers, f guessed, k1 = -0.08
  const auto scene = MakeSyntheticScene(so);
  const auto out = RunAndEvaluate(scene);
  ASSERT_FALSE(out.result.models.empty());
  const auto& rec = out.result.models[0];
  EXPECT_EQ(rec.images.size(), scene.input.images.size());
  EXPECT_LE(out.eval.centre_rmse_fraction, 0.0002);
  EXPECT_LE(out.eval.median_rotation_error_deg, 0.03);
  EXPECT_LE(out.eval.focal_relative_error, 0.001);
  EXPECT_NEAR(rec.cameras.begin()->second.k1, so.k1, 0.01);  // k2 (truth 0) is free and trades with k1
  EXPECT_LE(rec.MeanReprojectionError(), 0.9);               // ≈ the 0.5 px noise (mean of |2D noise| is 0.63 px)
  EXPECT_TRUE(out.result.left_out.empty());
  // The tracks against the union–find tracks of the matches (10% of them wrong): the model's figure is COLMAP's
  // (observations / points), and it holds nearly every keypoint of the tracks it touches.
  ASSERT_TRUE(out.result.stats.tracks.largest_model.has_value());
  const TrackCoverage& tracks = *out.result.stats.tracks.largest_model;
  EXPECT_DOUBLE_EQ(static_cast<double>(tracks.observations) / tracks.points, rec.MeanTrackLength());
  EXPECT_GE(tracks.held_of_touched_tracks, 0.9 * tracks.keypoints_of_touched_tracks);
  rec.Validate();
}

// A short orbit whose two-view scan can only bound the focal from below (a flat curve): the first mapping grows
// at that bound and refines it by ~27%; the images are mapped again from the refined focal, which must end closer
// to the truth than the single mapping does.
TEST(IncrementalMapper, FocalFarFromItsStartMapsAgainFromTheRefinedFocal) {
  SyntheticSceneOptions so;
  so.num_cameras = 10;
  so.num_points = 500;
  const auto scene = MakeSyntheticScene(so);
  MapperOptions once;
  once.focal_restart_min_change = 0;
  const auto single = RunAndEvaluate(scene, once);
  const auto twice = RunAndEvaluate(scene);
  ASSERT_FALSE(single.result.models.empty());
  ASSERT_FALSE(twice.result.models.empty());
  EXPECT_FALSE(single.result.focal_decision[0].restart.has_value());
  const FocalDecision& d = twice.result.focal_decision[0];
  EXPECT_EQ(d.kind, FocalDecisionKind::kRestart);
  ASSERT_TRUE(d.restart.has_value());
  EXPECT_TRUE(d.restart->kept);
  EXPECT_GT(d.restart->change, MapperOptions{}.focal_restart_min_change);
  EXPECT_EQ(d.restart->first_images, single.result.models[0].images.size());
  EXPECT_NEAR(d.restart->first_final_px, single.result.models[0].cameras.begin()->second.f, 1e-6);
  EXPECT_EQ(twice.result.models[0].images.size(), scene.input.images.size());
  EXPECT_LT(twice.eval.focal_relative_error, single.eval.focal_relative_error);
  EXPECT_LE(twice.eval.focal_relative_error, 0.005);
  EXPECT_LE(twice.eval.centre_rmse_fraction, single.eval.centre_rmse_fraction);
}

// A longer orbit whose focal leaves the scan's start once the model has grown: the first mapping stops growing
// there (what it would add under the wrong focal is mapped again anyway), and the second mapping ends as well as
// it does after a full first mapping.
TEST(IncrementalMapper, FocalThatLeavesItsStartStopsTheFirstMappingEarly) {
  SyntheticSceneOptions so;
  so.num_cameras = 24;
  so.num_points = 400;
  so.focal = 1300;  // between the dolly-zoom scan's steps (768, 1086, 1536 px): growth refines it by ~20%
  const auto scene = MakeSyntheticScene(so);
  MapperOptions at_end;
  at_end.focal_restart_min_images = 1000;  // the move is checked on the finished first model only
  const auto full = RunAndEvaluate(scene, at_end);
  const auto early = RunAndEvaluate(scene);
  ASSERT_FALSE(full.result.models.empty());
  ASSERT_FALSE(early.result.models.empty());
  ASSERT_TRUE(full.result.focal_decision[0].restart.has_value());
  EXPECT_FALSE(full.result.focal_decision[0].restart->early);
  const FocalDecision& d = early.result.focal_decision[0];
  ASSERT_TRUE(d.restart.has_value());
  EXPECT_TRUE(d.restart->early);
  EXPECT_TRUE(d.restart->kept);
  EXPECT_GE(d.restart->first_images, static_cast<size_t>(MapperOptions{}.focal_restart_min_images));
  EXPECT_LT(d.restart->first_images, scene.input.images.size());
  EXPECT_GT(d.restart->change, MapperOptions{}.focal_restart_min_change);
  EXPECT_EQ(early.result.models[0].images.size(), scene.input.images.size());
  EXPECT_LE(early.eval.focal_relative_error, 0.005);
  EXPECT_LE(early.eval.centre_rmse_fraction, 1.25 * full.eval.centre_rmse_fraction);
  EXPECT_LE(early.eval.median_rotation_error_deg, 1.25 * full.eval.median_rotation_error_deg);
}

TEST(IncrementalMapper, NadirGridOverNearPlanarTerrain) {
  SyntheticSceneOptions so;
  so.layout = SyntheticSceneOptions::Layout::kNadirGrid;
  so.num_cameras = 32;
  so.num_points = 1500;
  const auto scene = MakeSyntheticScene(so);
  const auto out = RunAndEvaluate(scene);
  ASSERT_FALSE(out.result.models.empty());
  EXPECT_EQ(out.result.models[0].images.size(), scene.input.images.size());
  EXPECT_LE(out.eval.centre_rmse_fraction, 0.001);
  EXPECT_LE(out.result.models[0].MeanReprojectionError(), 0.9);
}

// Telephoto video (the real FMV case): 360x240 frames through a ~2.6° field of view (f = 8000 px, 18.5 x the
// 1.2·max(w, h) guess), a 40° arc of an oblique orbit 160 m out, sequential pairs only. Every pair is
// near-affine; the focal must come from the scan (not the guess) and distortion must stay fixed.
TEST(IncrementalMapper, TelephotoOrbitFindsTheLongFocal) {
  SyntheticSceneOptions so;
  so.width = 360;
  so.height = 240;
  so.focal = 8000;
  so.k1 = 0;
  so.num_cameras = 40;
  so.num_points = 800;
  so.orbit_radius = 160;
  so.orbit_height = 60;
  so.orbit_arc_deg = 40;
  so.max_pair_gap = 8;
  so.noise_px = 0.3;
  const auto scene = MakeSyntheticScene(so);
  const auto out = RunAndEvaluate(scene);
  ASSERT_FALSE(out.result.models.empty());
  const auto& rec = out.result.models[0];
  EXPECT_GE(rec.images.size(), 0.9 * scene.input.images.size());
  EXPECT_LE(out.eval.median_rotation_error_deg, 0.1);
  EXPECT_LE(out.eval.focal_relative_error, 0.3);   // the guess is 95% off; near-affine views bound f weakly
  EXPECT_EQ(rec.cameras.begin()->second.k1, 0.0);  // narrow field: held at the prior
  EXPECT_LE(rec.MeanReprojectionError(), 0.6);
}

// An action camera's wide lens (854x480, f 450 px: ~87° across as a pinhole, k1 −0.27, k2 0.08 moving the corners
// by tens of pixels) with the focal only guessed (1.2 · 854, 2.3x too long): no pinhole essential matrix explains
// its pairs, so the pinhole focal scan alone reads a plateau and holds focal and distortion at a wrong bound.
// The distortion it detects must start the model as a wide lens with both free.
TEST(IncrementalMapper, WideLensDecidesFocalAndDistortion) {
  SyntheticSceneOptions so;
  so.width = 854;
  so.height = 480;
  so.focal = 450;
  so.k1 = -0.27;
  so.k2 = 0.08;
  so.num_cameras = 12;  // fewer than the telephoto dolly-zoom scan waits for
  so.num_points = 1500;
  so.noise_px = 0.3;
  so.orbit_radius = 4.5;  // close to the scene's disc (radius 3): it fills the wide view to the corners
  so.orbit_height = 1.5;
  so.orbit_arc_deg = 120;
  so.max_pair_gap = 4;
  const auto scene = MakeSyntheticScene(so);
  const auto out = RunAndEvaluate(scene);
  ASSERT_FALSE(out.result.models.empty());
  const auto& rec = out.result.models[0];
  EXPECT_EQ(rec.images.size(), scene.input.images.size());
  EXPECT_LE(out.eval.focal_relative_error, 0.01);
  // The points of this small scene rarely reach the corners, where the lens is extrapolated: 1.7 px there (a
  // plateau-held pinhole model is 140 px off).
  EXPECT_LE(out.eval.lens_residual_corner_px, 3);
  EXPECT_LE(out.eval.median_rotation_error_deg, 0.1);
  ASSERT_EQ(out.result.focal_decision.size(), out.result.models.size());
  EXPECT_EQ(out.result.focal_decision[0].kind, FocalDecisionKind::kDistorted);
}

// Bad input: unrelated images, a frame without features, a frame with too few matches, matches with indices
// out of range. The scene still reconstructs; each bad frame is left out with a reason; nothing throws.
TEST(IncrementalMapper, BadInputIsLeftOutWithAReason) {
  SyntheticSceneOptions so;
  so.num_cameras = 12;
  so.num_points = 600;
  so.guess_focal_factor = 0;  // known focal: this test is about bad frames
  auto scene = MakeSyntheticScene(so);
  auto& in = scene.input;
  std::mt19937_64 rng(3);
  // Two unrelated images, matched to each other with random (geometrically meaningless) matches.
  for (uint32_t id : {100u, 101u}) {
    MapperImage im;
    im.id = id;
    im.name = "unrelated-" + std::to_string(id) + ".png";
    for (int k = 0; k < 500; ++k) im.keypoints.emplace_back(rng() % 1280 + 0.5, rng() % 720 + 0.5);
    in.images.push_back(im);
  }
  features::VerifiedPair junk;
  junk.image_id1 = 100;
  junk.image_id2 = 101;
  for (uint32_t k = 0; k < 200; ++k) junk.inliers.push_back({k, static_cast<uint32_t>(rng() % 500)});
  in.pairs.push_back(junk);
  // A blank frame (no features) and one with a handful of matches to image 1.
  MapperImage blank;
  blank.id = 102;
  blank.name = "blank.png";
  in.images.push_back(blank);
  MapperImage weak;
  weak.id = 103;
  weak.name = "weak.png";
  for (int k = 0; k < 10; ++k) weak.keypoints.emplace_back(100 + 10 * k, 200);
  in.images.push_back(weak);
  features::VerifiedPair few;
  few.image_id1 = 1;
  few.image_id2 = 103;
  for (uint32_t k = 0; k < 8; ++k) few.inliers.push_back({k, k});
  in.pairs.push_back(few);
  // Out-of-range indices and an unknown image id.
  features::VerifiedPair broken;
  broken.image_id1 = 2;
  broken.image_id2 = 3;
  broken.inliers.push_back({1000000, 5});
  in.pairs.push_back(broken);
  broken.image_id2 = 999;
  in.pairs.push_back(broken);

  MapperResult result;
  ASSERT_NO_THROW(result = RunIncrementalMapper(in, {}));
  ASSERT_FALSE(result.models.empty());
  EXPECT_EQ(result.models[0].images.size(), 12u);
  for (uint32_t id : {100u, 101u, 102u, 103u}) {
    ASSERT_TRUE(result.left_out.count(id)) << id;
    EXPECT_FALSE(result.left_out.at(id).empty());
  }
  EXPECT_NE(result.left_out.at(102).find("no features"), std::string::npos) << result.left_out.at(102);
  EXPECT_NE(result.left_out.at(103).find("too few"), std::string::npos) << result.left_out.at(103);
  EXPECT_EQ(result.left_out.size(), 4u);
  const auto ev = EvaluateSparse(result.models[0], scene.truth);
  EXPECT_LE(ev.centre_rmse_fraction, 0.001);
}

// Views from one camera centre (a pan/tilt of a hovering platform): each pair of them is a pure rotation.
// Appends `n` such images (ids from first_id), all looking at the scene's points, with exact correspondences
// between consecutive ones and, when with_image1, to image 1.
void AddPureRotationImages(SyntheticScene* scene, uint32_t first_id, int n, const Eigen::Vector3d& centre,
                           bool with_image1) {
  auto& in = scene->input;
  const core::Camera cam = in.cameras.at(1).camera;
  std::vector<std::map<uint64_t, uint32_t>> seen;  // point id → keypoint index, per added image
  // Looks at the centroid of the truth points, panned by a few degrees per image.
  Eigen::Vector3d target = Eigen::Vector3d::Zero();
  for (const auto& [pid, p] : scene->truth.points) target += p.xyz;
  target /= std::max<size_t>(1, scene->truth.points.size());
  // The true camera (with its distortion) when the views join a synthetic flight; the prior otherwise, so a
  // rotation-only set is exactly a pure rotation under the model the mapper starts from.
  const core::Camera truth_cam = with_image1 ? scene->truth.cameras.begin()->second : cam;
  for (int k = 0; k < n; ++k) {
    const Eigen::Vector3d z = (target - centre).normalized();
    const Eigen::Vector3d pan = Eigen::AngleAxisd(0.04 * (k - n / 2.0), Eigen::Vector3d::UnitZ()) * z;
    const Eigen::Vector3d x = pan.cross(Eigen::Vector3d::UnitZ()).normalized(), y = pan.cross(x);
    Eigen::Matrix3d R;
    R.row(0) = x;
    R.row(1) = y;
    R.row(2) = pan;
    const core::Pose pose(Eigen::Quaterniond(R), -R * centre);
    MapperImage im;
    im.id = first_id + k;
    im.name = "rotation-" + std::to_string(k) + ".png";
    std::map<uint64_t, uint32_t> ids;
    for (const auto& [pid, p] : scene->truth.points) {
      const Eigen::Vector3d xc = pose.Transform(p.xyz);
      if (xc.z() <= 0) continue;
      const Eigen::Vector2d uv = truth_cam.Project(xc);
      if (uv.x() < 0 || uv.y() < 0 || uv.x() > cam.width || uv.y() > cam.height) continue;
      ids[pid] = static_cast<uint32_t>(im.keypoints.size());
      im.keypoints.push_back(uv);
    }
    in.images.push_back(im);
    seen.push_back(ids);
  }
  auto pair_of = [&](uint32_t id1, const std::map<uint64_t, uint32_t>& a, uint32_t id2,
                     const std::map<uint64_t, uint32_t>& b) {
    features::VerifiedPair vp;
    vp.image_id1 = id1;
    vp.image_id2 = id2;
    for (const auto& [pid, ka] : a)
      if (auto it = b.find(pid); it != b.end()) vp.inliers.push_back({ka, it->second});
    vp.num_inliers_H = static_cast<uint32_t>(vp.inliers.size());  // a homography explains every match
    vp.geometry = features::PairGeometry::kPlanarOrRotation;
    if (vp.inliers.size() >= 30) in.pairs.push_back(vp);
  };
  for (int k = 0; k + 1 < n; ++k)
    for (int j = k + 1; j < n && j <= k + 3; ++j) pair_of(first_id + k, seen[k], first_id + j, seen[j]);
  if (with_image1) {
    // Image 1's keypoints are shuffled: find each point's keypoint by its true projection (noise is 0.5 px).
    const auto& pose1 = scene->truth.images.at(1).pose;
    const auto& kps1 = in.images.front().keypoints;
    std::map<uint64_t, uint32_t> ids1;
    for (const auto& [pid, p] : scene->truth.points) {
      const Eigen::Vector3d xc = pose1.Transform(p.xyz);
      if (xc.z() <= 0) continue;
      const Eigen::Vector2d uv = truth_cam.Project(xc);
      for (uint32_t kp = 0; kp < kps1.size(); ++kp)
        if ((kps1[kp] - uv).norm() < 2.5) {
          ids1[pid] = kp;
          break;
        }
    }
    for (int k = 0; k < n; ++k) pair_of(1, ids1, first_id + k, seen[k]);
  }
}

// A pure-rotation segment within a flight: its frames see triangulated points, so they register by absolute
// pose even though no pair among them has a baseline; the rest of the flight is unaffected.
TEST(IncrementalMapper, PureRotationSegmentRegistersByAbsolutePose) {
  SyntheticSceneOptions so;
  so.num_cameras = 12;
  so.num_points = 600;
  so.guess_focal_factor = 0;
  auto scene = MakeSyntheticScene(so);
  const Eigen::Vector3d c1 = scene.truth.images.at(1).pose.Centre();
  AddPureRotationImages(&scene, 200, 5, c1, true);
  MapperResult result;
  ASSERT_NO_THROW(result = RunIncrementalMapper(scene.input, {}));
  ASSERT_FALSE(result.models.empty());
  const auto& rec = result.models[0];
  EXPECT_EQ(rec.images.size(), 17u);
  for (const auto& [id, why] : result.left_out) ADD_FAILURE() << id << ": " << why;
  const auto ev = EvaluateSparse(rec, scene.truth);  // truth has the 12 orbit cameras
  EXPECT_LE(ev.centre_rmse_fraction, 0.001);
  // The rotation frames sit at image 1's centre.
  for (uint32_t id = 200; id < 205; ++id)
    if (rec.images.count(id)) {
      const double d = (rec.images.at(id).pose.Centre() - rec.images.at(1).pose.Centre()).norm();
      const double extent = (rec.images.at(1).pose.Centre() - rec.images.at(7).pose.Centre()).norm();
      EXPECT_LT(d, 0.01 * extent) << id;
    }
}

// Impostors: image x also "looks like" the camera opposite it on the orbit (a symmetric building seen from the
// other side): part of that camera's keypoints are copied into x and matched to it and its next neighbour. When
// x is tried before its true neighbours are in the model, the copies are all its support and it registers at the
// opposite camera's pose; the final relocalisation must move it back. Four impostors around the orbit, so at
// least one is tried early whatever the initial pair.
TEST(IncrementalMapper, ImageRegisteredOnAmbiguousMatchesIsRelocalised) {
  SyntheticSceneOptions so;
  so.num_cameras = 24;
  so.num_points = 1500;
  so.guess_focal_factor = 0;
  so.k1 = 0;
  so.max_pair_gap = 3;
  auto scene = MakeSyntheticScene(so);
  auto pair_of = [&](uint32_t a, uint32_t b) -> const features::VerifiedPair* {
    for (const auto& p : scene.input.pairs)
      if (p.image_id1 == std::min(a, b) && p.image_id2 == std::max(a, b)) return &p;
    return nullptr;
  };
  const std::vector<uint32_t> impostors = {4, 10, 16, 22};  // ids (camera index + 1)
  for (uint32_t x : impostors) {
    const uint32_t w = (x - 1 + 12) % 24 + 1, w1 = w % 24 + 1;  // the opposite camera and its neighbour
    const features::VerifiedPair* ww1 = pair_of(w, w1);
    ASSERT_NE(ww1, nullptr);
    auto& xk = scene.input.images[x - 1].keypoints;
    const auto& wk = scene.input.images[w - 1].keypoints;
    features::VerifiedPair to_w, to_w1;
    for (size_t i = 0; i < ww1->inliers.size(); i += 2) {  // half of the shared points
      const auto& m = ww1->inliers[i];
      const uint32_t kw = w < w1 ? m.idx1 : m.idx2, kw1 = w < w1 ? m.idx2 : m.idx1;
      const uint32_t kx = static_cast<uint32_t>(xk.size());
      xk.push_back(wk[kw]);
      scene.input.images[x - 1].colors.push_back(scene.input.images[x - 1].colors.back());
      to_w.inliers.push_back(x < w ? features::FeatureMatch{kx, kw} : features::FeatureMatch{kw, kx});
      to_w1.inliers.push_back(x < w1 ? features::FeatureMatch{kx, kw1} : features::FeatureMatch{kw1, kx});
    }
    for (auto [pair, other] : {std::pair{&to_w, w}, std::pair{&to_w1, w1}}) {
      pair->image_id1 = std::min(x, other);
      pair->image_id2 = std::max(x, other);
      pair->num_putative = pair->num_inliers_F = static_cast<uint32_t>(pair->inliers.size());
      pair->geometry = features::PairGeometry::kUncalibrated;
      scene.input.pairs.push_back(*pair);
    }
  }
  auto wrong = [&](const core::Reconstruction& rec) {
    const auto ev = EvaluateSparse(rec, scene.truth);
    const double extent = ev.extent;
    int n = 0;
    for (uint32_t x : impostors) {
      if (!rec.images.count(x)) continue;
      const Eigen::Vector3d c = ev.alignment.Apply(rec.images.at(x).pose.Centre());
      n += (c - scene.truth.images.at(x).pose.Centre()).norm() > 0.01 * extent;
    }
    return n;
  };
  MapperOptions off;
  off.relocalise = false;
  const auto trapped = RunIncrementalMapper(scene.input, off);
  ASSERT_FALSE(trapped.models.empty());
  EXPECT_GE(wrong(trapped.models[0]), 1) << "no impostor registered at the wrong pose: the test lost its point";
  const auto fixed = RunIncrementalMapper(scene.input, {});
  ASSERT_FALSE(fixed.models.empty());
  const auto& rec = fixed.models[0];
  EXPECT_EQ(rec.images.size(), 24u);
  EXPECT_EQ(wrong(rec), 0);
  EXPECT_GE(fixed.stats.relocalised_images, 1);
  EXPECT_LE(EvaluateSparse(rec, scene.truth).centre_rmse_fraction, 0.001);
}

// Nothing but a pure rotation: no pair has a baseline, so no model can be made. The mapper must say so for every
// frame and return, not throw or loop.
TEST(IncrementalMapper, OnlyPureRotationGivesNoModelAndReasons) {
  SyntheticSceneOptions so;
  so.num_cameras = 12;
  so.num_points = 600;
  so.guess_focal_factor = 0;
  auto scene = MakeSyntheticScene(so);
  SyntheticScene rot;
  rot.truth = scene.truth;
  rot.input.cameras = scene.input.cameras;
  AddPureRotationImages(&rot, 1, 8, scene.truth.images.at(1).pose.Centre(), false);
  MapperResult result;
  ASSERT_NO_THROW(result = RunIncrementalMapper(rot.input, {}));
  EXPECT_TRUE(result.models.empty());
  EXPECT_EQ(result.left_out.size(), 8u);
  for (const auto& [id, why] : result.left_out) EXPECT_FALSE(why.empty()) << id;
}

TEST(IncrementalMapper, NothingToReconstruct) {
  MapperInput in;
  in.cameras[1].camera = core::Camera::Pinhole(640, 480, 600);
  MapperResult r;
  ASSERT_NO_THROW(r = RunIncrementalMapper(in, {}));
  EXPECT_TRUE(r.models.empty());
  MapperImage a;
  a.id = 1;
  a.name = "a.png";
  a.camera_id = 7;  // unknown camera: inconsistent input is a user error
  in.images.push_back(a);
  EXPECT_THROW(RunIncrementalMapper(in, {}), Error);
}

}  // namespace
}  // namespace fmv3d::sfm
