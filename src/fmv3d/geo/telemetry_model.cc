#include "fmv3d/geo/telemetry_model.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "fmv3d/core/error.h"
#include "fmv3d/core/stats.h"
#include "fmv3d/geometry/triangulation.h"
#include "fmv3d/sfm/bundle_adjustment.h"

namespace fmv3d::geo {
namespace {

// Drops observations whose reprojection error exceeds max_px, then points left with fewer than two.
size_t DropBadObservations(core::Reconstruction* rec, double max_px) {
  size_t removed = 0;
  for (auto it = rec->points.begin(); it != rec->points.end();) {
    auto& p = it->second;
    std::vector<core::TrackElement> kept;
    for (const auto& el : p.track) {
      if (sfm::ObservationError(*rec, el.image_id, el.point2d_idx, p.xyz) <= max_px) {
        kept.push_back(el);
      } else {
        rec->images.at(el.image_id).point3d_ids[el.point2d_idx] = core::kNoPoint3D;
        ++removed;
      }
    }
    p.track = std::move(kept);
    if (p.track.size() < 2) {
      for (const auto& el : p.track) rec->images.at(el.image_id).point3d_ids[el.point2d_idx] = core::kNoPoint3D;
      it = rec->points.erase(it);
    } else {
      ++it;
    }
  }
  return removed;
}

// Camera-to-ENU rotation of a keyframe from its telemetry: the full ST 0601 angle chain when present, else the
// line of sight from the sensor to the frame centre (EG0104), with no roll about it (image rows level); and the
// ground height under the frame centre. nullopt when the telemetry has neither.
struct TelemetryView {
  Eigen::Matrix3d camera_to_enu;
  std::optional<double> ground_z;
};
std::optional<TelemetryView> ViewFromTelemetry(const GeorefPair& p, const LocalFrame& frame) {
  const Eigen::Vector3d c = frame.ToEnu(p.pos);
  std::optional<double> ground_z;
  std::optional<Eigen::Vector3d> target;
  if (p.frame_centre && p.slant_range && *p.slant_range > 0) {
    GeoPoint fc = *p.frame_centre;
    fc.alt = p.pos.alt;  // horizontal position only: the height follows from the slant range
    const Eigen::Vector3d f = frame.ToEnu(fc);
    const double horizontal = (f - c).head<2>().norm();
    if (horizontal < *p.slant_range) {
      const double drop = std::sqrt(*p.slant_range * *p.slant_range - horizontal * horizontal);
      target = Eigen::Vector3d(f.x(), f.y(), c.z() - drop);
      ground_z = c.z() - drop;
    }
  }
  if (p.attitude) return TelemetryView{*p.attitude, ground_z};
  if (!target) return std::nullopt;
  const Eigen::Vector3d d = (*target - c).normalized();
  const Eigen::Vector3d x = d.cross(Eigen::Vector3d::UnitZ());
  if (x.norm() < 1e-6) return std::nullopt;  // looking straight down: the roll is undefined
  TelemetryView v;
  v.camera_to_enu.col(0) = x.normalized();
  v.camera_to_enu.col(2) = d;
  v.camera_to_enu.col(1) = d.cross(v.camera_to_enu.col(0));
  v.ground_z = ground_z;
  return v;
}

struct TelemetryCameras {
  std::map<uint32_t, Eigen::Vector3d> centres, axes;  // by image id, ENU
  std::vector<double> ground;                         // ground heights under the frame centres
};

// Puts every keyframe with a telemetry view at its telemetry pose and removes the frames without one.
TelemetryCameras PlaceCameras(const std::vector<GeorefPair>& keyframes, const LocalFrame& frame,
                              core::Reconstruction* rec, size_t* left_out) {
  TelemetryCameras out;
  for (const auto& p : keyframes) {
    const core::Image* img = rec->FindImageByName(p.name);
    if (!img) continue;
    const auto v = ViewFromTelemetry(p, frame);
    if (!v) continue;
    const Eigen::Vector3d c = frame.ToEnu(p.pos);
    auto& pose = rec->images.at(img->id).pose;
    pose.q = Eigen::Quaterniond(v->camera_to_enu.transpose()).normalized();
    pose.t = -(pose.q * c);
    out.centres[img->id] = c;
    out.axes[img->id] = v->camera_to_enu.col(2);
    if (v->ground_z) out.ground.push_back(*v->ground_z);
  }
  if (out.centres.size() < 3)
    throw Error(fmt::format("georef: only {} keyframes have a telemetry attitude or frame centre (3 needed)",
                            out.centres.size()));
  std::vector<uint32_t> drop;
  for (const auto& [id, im] : rec->images)
    if (!out.centres.count(id)) drop.push_back(id);
  for (uint32_t id : drop) {
    for (int64_t pid : rec->images.at(id).point3d_ids) {
      if (pid == core::kNoPoint3D) continue;
      auto& track = rec->points.at(static_cast<uint64_t>(pid)).track;
      track.erase(
          std::remove_if(track.begin(), track.end(), [id](const core::TrackElement& e) { return e.image_id == id; }),
          track.end());
    }
    rec->images.erase(id);
  }
  *left_out = drop.size();
  return out;
}

// The whole prior camera where the intrinsics came from the telemetry's HFOV: the image model's distortion was
// fitted along with its degenerate shape (a synthetic telephoto pass: k2 −1.84 on a lens without distortion).
std::vector<TelemetryFocal> UseTelemetryCameras(const io::FramesIndex& index, core::Reconstruction* rec) {
  std::vector<TelemetryFocal> focal;
  for (const auto& cp : index.cameras) {
    const auto it = rec->cameras.find(cp.camera.id);
    if (it == rec->cameras.end() || cp.prior_source.kind != io::PriorKind::kTelemetryHfov) continue;
    focal.push_back({cp.camera.id, cp.camera.f, it->second.f, it->second.k1, it->second.k2});
    const uint32_t id = it->second.id;
    it->second = cp.camera;
    it->second.id = id;
  }
  return focal;
}

// Every point starts where its middle observation's ray meets the ground plane at ground_z (a telephoto clip's
// rays are too close to parallel to triangulate before the attitudes are refined); without it, it is
// triangulated from the telemetry cameras. Points that cannot be placed leave the model.
void StartPoints(const std::optional<double>& ground_z, core::Reconstruction* rec) {
  for (auto it = rec->points.begin(); it != rec->points.end();) {
    auto& p = it->second;
    bool placed = false;
    if (p.track.size() >= 2 && ground_z) {
      const auto& el = p.track[p.track.size() / 2];
      const auto& im = rec->images.at(el.image_id);
      const Eigen::Vector3d ray =
          im.pose.q.conjugate() * rec->cameras.at(im.camera_id).Unproject(im.points2d[el.point2d_idx]);
      const Eigen::Vector3d c = im.pose.Centre();
      if (ray.z() < -1e-9) {
        p.xyz = c + (*ground_z - c.z()) / ray.z() * ray;
        placed = true;
      }
    } else if (p.track.size() >= 2) {
      std::vector<core::Pose> poses;
      std::vector<Eigen::Vector2d> rays;
      for (const auto& el : p.track) {
        const auto& im = rec->images.at(el.image_id);
        poses.push_back(im.pose);
        rays.push_back(rec->cameras.at(im.camera_id).Unproject(im.points2d[el.point2d_idx]).head<2>());
      }
      Eigen::Vector3d X;
      placed = geometry::TriangulateDLT(poses, rays, &X);
      for (const auto& pose : poses) placed = placed && geometry::HasPositiveDepth(pose, X);
      if (placed) p.xyz = X;
    }
    if (!placed) {
      for (const auto& el : p.track) rec->images.at(el.image_id).point3d_ids[el.point2d_idx] = core::kNoPoint3D;
      it = rec->points.erase(it);
    } else {
      ++it;
    }
  }
}

// Frame centres at their slant range as priors (the point along each optical axis), weighed by their own
// scatter about the adjusted model, which they then tighten: estimated again after each adjustment until it
// settles (a platform's own, metres-off frame centres end with little weight).
void AdjustWithSightPriors(const std::map<std::string, std::pair<Eigen::Vector3d, double>>& frame_centres,
                           const sfm::BundleAdjustmentOptions& ba, sfm::BundleAdjustmentConfig* config,
                           core::Reconstruction* rec, sfm::BundleAdjustmentSummary* last, TelemetryModel* out) {
  for (const auto& [id, img] : rec->images) {
    const auto it = frame_centres.find(img.name);
    if (it != frame_centres.end()) config->sight_priors[id] = it->second;
  }
  for (int round = 0; config->sight_priors.size() >= 3 && round < 5; ++round) {
    std::vector<double> norms;
    for (const auto& [id, fr] : config->sight_priors) {
      const core::Pose& pose = rec->images.at(id).pose;
      norms.push_back((pose.Centre() + fr.second * (pose.q.conjugate() * Eigen::Vector3d::UnitZ()) - fr.first).norm());
    }
    const double sigma_fc = std::max(0.005, core::Median(norms) / 1.538);  // per axis, from the 3D median (χ₃)
    out->frame_centre_prior_sigma_m.push_back(sigma_fc);
    if (round > 0 && sigma_fc > 0.8 * config->sight_prior_sigma) break;  // settled
    config->sight_prior_sigma = sigma_fc;
    const auto r = sfm::BundleAdjust(rec, *config, ba);
    if (!r.success) break;
    *last = r;
  }
  if (config->sight_priors.size() < 3) config->sight_priors.clear();
  out->frame_centre_priors = config->sight_priors.size();
}

}  // namespace

nlohmann::json TelemetryModel::ToJson(const TelemetryModelOptions& o) const {
  nlohmann::json focal = nlohmann::json::array();
  for (const TelemetryFocal& t : focal_from_telemetry)
    focal.push_back({{"camera", t.camera},
                     {"f_image_model", t.f_image_model},
                     {"f", t.f},
                     {"k1_image_model", t.k1_image_model},
                     {"k2_image_model", t.k2_image_model}});
  return {{"keyframes", keyframes},
          {"frames_left_out", frames_left_out},
          {"ground_z_start_m", ground_z_start ? nlohmann::json(*ground_z_start) : nlohmann::json()},
          {"focal_from_telemetry", focal},
          {"prior_sigma_m", o.prior_sigma_m},
          {"attitude_sigma_deg", o.attitude_sigma_deg},
          {"mean_reprojection_px_start", mean_reprojection_px_start},
          {"reprojection_rms_px", reprojection_rms_px},
          {"points", model.points.size()},
          {"observations_dropped", observations_dropped},
          {"frame_centre_priors", frame_centre_priors},
          {"frame_centre_prior_sigma_m", frame_centre_prior_sigma_m},
          {"centre_rms_from_telemetry_m", centre_rms_from_telemetry_m}};
}

TelemetryModel BuildTelemetryModel(const io::FramesIndex& index, const core::Reconstruction& image_model,
                                   const std::vector<GeorefPair>& keyframes,
                                   const std::map<std::string, std::pair<Eigen::Vector3d, double>>& frame_centres,
                                   const LocalFrame& frame, const TelemetryModelOptions& o) {
  TelemetryModel out;
  core::Reconstruction& rec = out.model;
  rec = image_model;
  const TelemetryCameras cams = PlaceCameras(keyframes, frame, &rec, &out.frames_left_out);
  out.keyframes = cams.centres.size();
  out.focal_from_telemetry = UseTelemetryCameras(index, &rec);
  if (!cams.ground.empty()) out.ground_z_start = core::Median(cams.ground);
  StartPoints(out.ground_z_start, &rec);
  sfm::BundleAdjustmentConfig config;
  config.centre_priors = cams.centres;
  config.centre_prior_sigma = o.prior_sigma_m;
  config.centre_prior_huber = 1e6;
  // The optical axes hold the rotation about the flight line, which straight-line positions leave free.
  config.axis_priors = cams.axes;
  config.axis_prior_sigma_rad = o.attitude_sigma_deg * M_PI / 180;
  for (const auto& [id, cam] : rec.cameras) config.constant_cameras.insert(id);
  sfm::BundleAdjustmentOptions ba;
  ba.max_iterations = 200;
  ba.loss = sfm::BundleAdjustmentOptions::Loss::kTrivial;
  ba.refine_k1 = ba.refine_k2 = false;
  sfm::UpdatePointErrors(&rec);
  out.mean_reprojection_px_start = rec.MeanReprojectionError();
  const auto plain = sfm::BundleAdjust(&rec, config, ba);
  out.observations_dropped = DropBadObservations(&rec, 10.0);
  ba.loss = sfm::BundleAdjustmentOptions::Loss::kCauchy;
  ba.loss_scale_px = 1.0;
  sfm::BundleAdjust(&rec, config, ba);
  out.observations_dropped += DropBadObservations(&rec, 4.0);
  auto last = sfm::BundleAdjust(&rec, config, ba);
  if (!plain.success || !last.success) throw Error("georef: the bundle adjustment of the telemetry model failed");
  AdjustWithSightPriors(frame_centres, ba, &config, &rec, &last, &out);
  sfm::UpdatePointErrors(&rec);
  double prior_sq = 0;
  for (const auto& [id, c] : cams.centres) prior_sq += (rec.images.at(id).pose.Centre() - c).squaredNorm();
  out.reprojection_rms_px = last.final_rms_px;
  out.centre_rms_from_telemetry_m = std::sqrt(prior_sq / cams.centres.size());
  spdlog::info(
      "georef: telemetry-initialised model: {} keyframes, {} points, reprojection {:.2f} → {:.3f} px RMS, "
      "centres {:.2f} m RMS from the telemetry",
      out.keyframes, rec.points.size(), out.mean_reprojection_px_start, out.reprojection_rms_px,
      out.centre_rms_from_telemetry_m);
  return out;
}

double ReprojectionRms(const core::Reconstruction& rec) {
  double sq = 0;
  size_t n = 0;
  for (const auto& [id, img] : rec.images) {
    const core::Camera& cam = rec.cameras.at(img.camera_id);
    for (size_t k = 0; k < img.points2d.size(); ++k) {
      const auto pit = rec.points.find(static_cast<uint64_t>(img.point3d_ids[k]));
      if (img.point3d_ids[k] == core::kNoPoint3D || pit == rec.points.end()) continue;
      const Eigen::Vector3d xc = img.pose.Transform(pit->second.xyz);
      if (xc.z() <= 0) continue;
      sq += (cam.Project(xc) - img.points2d[k]).squaredNorm();
      ++n;
    }
  }
  return n ? std::sqrt(sq / n) : 0.0;
}

}  // namespace fmv3d::geo
