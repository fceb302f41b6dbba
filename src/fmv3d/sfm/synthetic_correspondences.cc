#include "fmv3d/sfm/synthetic_correspondences.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>

#include "fmv3d/core/error.h"

namespace fmv3d::sfm {

namespace {

// One random stream for the whole scene: every step draws from it in turn, so a scene depends only on the
// options and the seed. The normal distribution keeps state between draws (values come in pairs), so it is
// shared too.
struct SceneRandom {
  explicit SceneRandom(uint64_t seed) : rng(seed) {}
  std::mt19937_64 rng;
  std::uniform_real_distribution<double> uni{0, 1};
  std::normal_distribution<double> gauss{0, 1};
};

// Points with an outward normal: a point is seen only from the side its normal faces (self-occlusion).
struct ScenePoints {
  std::vector<Eigen::Vector3d> X, N;
};

ScenePoints MakeScenePoints(const SyntheticSceneOptions& o, SceneRandom* r) {
  ScenePoints pts;
  pts.X.resize(o.num_points);
  pts.N.resize(o.num_points);
  for (int i = 0; i < o.num_points; ++i) {
    if (o.layout == SyntheticSceneOptions::Layout::kOrbit) {
      const double a = 2 * M_PI * r->uni(r->rng), rad = 3.0 * std::sqrt(r->uni(r->rng));
      pts.X[i] = Eigen::Vector3d(rad * std::cos(a), rad * std::sin(a), -1.5 + 3.0 * r->uni(r->rng));
      pts.N[i] = Eigen::Vector3d(std::cos(a), std::sin(a), 0.5 * (r->uni(r->rng) - 0.5)).normalized();
    } else {
      // Gently rolling terrain 100 m x 60 m, heights within ±2 m: near-planar from 40 m up.
      const double x = -50 + 100 * r->uni(r->rng), y = -30 + 60 * r->uni(r->rng);
      pts.X[i] = Eigen::Vector3d(x, y, 2.0 * std::sin(x / 15.0) * std::cos(y / 11.0));
      pts.N[i] = Eigen::Vector3d::UnitZ();
    }
  }
  return pts;
}

std::vector<core::Pose> MakeScenePoses(const SyntheticSceneOptions& o, SceneRandom* r) {
  std::vector<core::Pose> poses(o.num_cameras);
  for (int c = 0; c < o.num_cameras; ++c) {
    if (o.layout == SyntheticSceneOptions::Layout::kOrbit) {
      const double a = o.orbit_arc_deg >= 360 ? 2 * M_PI * c / o.num_cameras
                                              : o.orbit_arc_deg * M_PI / 180 * c / std::max(1, o.num_cameras - 1);
      const double s = o.orbit_radius / 10;  // the default orbit's wobble, scaled
      const Eigen::Vector3d centre(o.orbit_radius * std::cos(a), o.orbit_radius * std::sin(a),
                                   o.orbit_height + 0.5 * s * std::sin(3 * a));
      poses[c] = core::Pose::LookAt(centre, Eigen::Vector3d(0, 0, 0.2 * std::cos(2 * a)));
    } else {
      // Lawn-mower: rows along x, 8 images per row; camera looking straight down with a little jitter.
      const int per_row = std::max(2, o.num_cameras / 4);
      const int row = c / per_row, k = c % per_row;
      const double x = -40 + 80.0 * (row % 2 ? per_row - 1 - k : k) / (per_row - 1);
      const double y = -20 + 12.0 * row;
      const Eigen::Vector3d centre(x, y, 40 + r->gauss(r->rng));
      // Two draws the pose does not use (a look-ahead target), kept so that a seed keeps giving the same scene.
      r->gauss(r->rng);
      r->gauss(r->rng);
      // Each vector's components drawn last first, one per statement: the scenes every seed has always given.
      const double target_y = y + 0.5 * r->gauss(r->rng);
      const double target_x = x + 0.5 * r->gauss(r->rng);
      poses[c] = core::Pose::LookAt(centre, Eigen::Vector3d(target_x, target_y, 0), Eigen::Vector3d::UnitY());
    }
  }
  return poses;
}

// Image c's keypoints (noisy projections of the points it sees, then clutter, in shuffled order) and its
// observations (point, keypoint index).
MapperImage ObserveScene(const SyntheticSceneOptions& o, const core::Camera& cam, const ScenePoints& pts,
                         const core::Pose& pose, int c, SceneRandom* r, std::vector<std::pair<int, uint32_t>>* obs) {
  MapperImage im;
  im.id = static_cast<uint32_t>(c + 1);
  im.camera_id = 1;
  char name[32];
  std::snprintf(name, sizeof name, "synth-%06d.png", c);
  im.name = name;
  std::vector<Eigen::Vector2d> kps;
  std::vector<int> pt;
  for (int i = 0; i < o.num_points; ++i) {
    const Eigen::Vector3d xc = pose.Transform(pts.X[i]);
    if (xc.z() <= 0.1) continue;
    if (pts.N[i].dot(pose.Centre() - pts.X[i]) <= 0.1 * (pose.Centre() - pts.X[i]).norm()) continue;
    const Eigen::Vector2d uv = cam.Project(xc);
    if (!cam.InImage(uv, 2)) continue;
    const double noise_v = r->gauss(r->rng);
    const double noise_u = r->gauss(r->rng);
    kps.push_back(uv + o.noise_px * Eigen::Vector2d(noise_u, noise_v));
    pt.push_back(i);
  }
  const int clutter = static_cast<int>(o.clutter_ratio * kps.size());
  for (int k = 0; k < clutter; ++k) {
    const double v = o.height * r->uni(r->rng);
    const double u = o.width * r->uni(r->rng);
    kps.emplace_back(u, v);
    pt.push_back(-1);
  }
  std::vector<uint32_t> perm(kps.size());
  std::iota(perm.begin(), perm.end(), 0u);
  std::shuffle(perm.begin(), perm.end(), r->rng);
  im.keypoints.resize(kps.size());
  im.colors.assign(kps.size(), Eigen::Matrix<uint8_t, 3, 1>(200, 150, 100));
  for (uint32_t k = 0; k < perm.size(); ++k) {
    im.keypoints[perm[k]] = kps[k];
    if (pt[k] >= 0) obs->emplace_back(pt[k], perm[k]);
  }
  return im;
}

// Pairs: the true matches shared by two cameras, with a fraction replaced by wrong ones.
std::vector<features::VerifiedPair> MakeScenePairs(const SyntheticSceneOptions& o,
                                                   const std::vector<std::vector<std::pair<int, uint32_t>>>& obs,
                                                   const std::vector<MapperImage>& images, SceneRandom* r) {
  std::vector<features::VerifiedPair> pairs;
  std::vector<std::map<int, uint32_t>> kp_of(o.num_cameras);
  for (int c = 0; c < o.num_cameras; ++c)
    for (const auto& [p, k] : obs[c]) kp_of[c][p] = k;
  for (int a = 0; a < o.num_cameras; ++a)
    for (int b = a + 1; b < o.num_cameras; ++b) {
      if (o.max_pair_gap > 0 && b - a > o.max_pair_gap) continue;
      features::VerifiedPair pair;
      pair.image_id1 = static_cast<uint32_t>(a + 1);
      pair.image_id2 = static_cast<uint32_t>(b + 1);
      for (const auto& [p, k] : kp_of[a]) {
        auto it = kp_of[b].find(p);
        if (it != kp_of[b].end()) pair.inliers.push_back({k, it->second});
      }
      if (static_cast<int>(pair.inliers.size()) < o.min_pair_matches) continue;
      const uint32_t nb = static_cast<uint32_t>(images[b].keypoints.size());
      for (auto& m : pair.inliers)
        if (r->uni(r->rng) < o.outlier_ratio) m.idx2 = static_cast<uint32_t>(r->rng() % nb);
      pair.num_putative = pair.num_inliers_F = static_cast<uint32_t>(pair.inliers.size());
      pair.geometry = features::PairGeometry::kUncalibrated;
      pairs.push_back(std::move(pair));
    }
  return pairs;
}

}  // namespace

SyntheticScene MakeSyntheticScene(const SyntheticSceneOptions& o) {
  if (o.num_cameras < 2 || o.num_points < 1 || o.width < 16 || o.height < 16 || !(o.focal > 0) || !(o.aspect > 0))
    throw Error("synthetic scene: invalid options");
  SceneRandom random(o.seed);
  SyntheticScene scene;
  core::Camera cam = core::Camera::Pinhole(o.width, o.height, o.focal);
  cam.u0 += o.u0_offset;
  cam.v0 += o.v0_offset;
  cam.aspect = o.aspect;
  cam.k1 = o.k1;
  cam.k2 = o.k2;
  scene.truth.cameras[1] = cam;
  const ScenePoints pts = MakeScenePoints(o, &random);
  const std::vector<core::Pose> poses = MakeScenePoses(o, &random);

  // Observations per camera (keypoint order shuffled, clutter added).
  std::vector<std::vector<std::pair<int, uint32_t>>> obs(o.num_cameras);  // (point, keypoint index)
  for (int c = 0; c < o.num_cameras; ++c) {
    MapperImage im = ObserveScene(o, cam, pts, poses[c], c, &random, &obs[c]);
    core::Image ti;
    ti.id = im.id;
    ti.camera_id = 1;
    ti.name = im.name;
    ti.pose = poses[c];
    scene.truth.images[ti.id] = ti;
    scene.input.images.push_back(std::move(im));
  }
  for (int i = 0; i < o.num_points; ++i) {
    core::Point3D p;
    p.id = static_cast<uint64_t>(i) + 1;
    p.xyz = pts.X[i];
    scene.truth.points[p.id] = p;
  }
  scene.input.pairs = MakeScenePairs(o, obs, scene.input.images, &random);

  MapperCamera prior;
  prior.camera = core::Camera::Pinhole(o.width, o.height, o.focal);
  prior.camera.id = 1;
  prior.focal_known = o.guess_focal_factor <= 0;
  if (!prior.focal_known) prior.camera.f = o.guess_focal_factor * std::max(o.width, o.height);
  scene.input.cameras[1] = prior;
  return scene;
}

core::Reconstruction TrueModelWithObservations(const SyntheticSceneOptions& so) {
  const auto scene = MakeSyntheticScene(so);
  core::Reconstruction rec = scene.truth;
  rec.points.clear();
  for (auto& [id, im] : rec.images) {
    const auto& mi = scene.input.images[id - 1];
    im.points2d = mi.keypoints;
    im.point3d_ids.assign(mi.keypoints.size(), core::kNoPoint3D);
  }
  // Recover which keypoint sees which point by projecting the truth (noise < 3 px, clutter far away).
  for (const auto& [pid, p] : scene.truth.points) {
    core::Point3D q = p;
    for (auto& [id, im] : rec.images) {
      const Eigen::Vector3d xc = im.pose.Transform(p.xyz);
      if (xc.z() <= 0) continue;
      const Eigen::Vector2d uv = rec.cameras.at(1).Project(xc);
      for (uint32_t k = 0; k < im.points2d.size(); ++k)
        if ((im.points2d[k] - uv).norm() < 4 * so.noise_px + 1e-9 && im.point3d_ids[k] == core::kNoPoint3D) {
          im.point3d_ids[k] = static_cast<int64_t>(pid);
          q.track.push_back({id, k});
          break;
        }
    }
    if (q.track.size() >= 2) {
      rec.points[pid] = q;
    } else {
      for (const auto& el : q.track) rec.images[el.image_id].point3d_ids[el.point2d_idx] = core::kNoPoint3D;
    }
  }
  return rec;
}

}  // namespace fmv3d::sfm
