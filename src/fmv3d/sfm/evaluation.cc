#include "fmv3d/sfm/evaluation.h"

#include <algorithm>
#include <cmath>
#include <filesystem>

#include "fmv3d/core/error.h"
#include "fmv3d/core/stats.h"
#include "fmv3d/geometry/similarity.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/io/ground_truth.h"

namespace fmv3d::sfm {

namespace fs = std::filesystem;

nlohmann::json SparseEvaluation::ToJson() const {
  return {{"truth_images", num_truth_images},
          {"matched_images", num_matched},
          {"centre_rmse", centre_rmse},
          {"extent", extent},
          {"extent_definition", "max pairwise distance between true camera centres"},
          {"centre_rmse_percent_of_extent", 100 * centre_rmse_fraction},
          {"max_centre_error_percent_of_extent", 100 * max_centre_error_fraction},
          {"median_relative_rotation_error_deg", median_rotation_error_deg},
          {"focal_relative_error_percent", 100 * focal_relative_error},
          {"focal_definition", "f = fy (vertical focal, pixels); fx = f * aspect"},
          {"focal_x_relative_error_percent", 100 * focal_x_relative_error},
          {"principal_point_error_px", principal_point_error_px},
          {"lens_residual_corner_px", lens_residual_corner_px},
          {"lens_residual_definition",
           "max over the image corners of the difference between the estimated and true distortion displacements "
           "(pixel minus its undistorted position under the same camera's pinhole)"},
          {"systematic_rotation_error_deg",
           {systematic_rotation_deg.x(), systematic_rotation_deg.y(), systematic_rotation_deg.z()}},
          {"systematic_rotation_error_definition",
           "mean over cameras of each camera's absolute rotation error (after the similarity), in its own axes: "
           "x = pitch (image rows), y = yaw (columns), z = roll"},
          {"alignment",
           {{"from",
             alignment_from == AlignmentSource::kCentres ? "camera centres" : "camera centres and viewing directions"},
            {"scale", alignment.s},
            {"q_wxyz", {alignment.q.w(), alignment.q.x(), alignment.q.y(), alignment.q.z()}},
            {"t", {alignment.t.x(), alignment.t.y(), alignment.t.z()}}}}};
}

double MedianRelativeRotationErrorDeg(const std::vector<core::Pose>& estimate, const std::vector<core::Pose>& truth) {
  std::vector<double> errs;
  for (size_t i = 0; i < estimate.size(); ++i)
    for (size_t j = i + 1; j < estimate.size(); ++j) {
      const Eigen::Quaterniond re = estimate[j].q * estimate[i].q.conjugate();
      const Eigen::Quaterniond rt = truth[j].q * truth[i].q.conjugate();
      errs.push_back(core::RotationAngle(re, rt) * 180.0 / M_PI);
    }
  return core::Median(std::move(errs));
}

double LensResidualPx(const core::Camera& estimate, const core::Camera& truth) {
  if (estimate.width != truth.width || estimate.height != truth.height)
    throw Error("evaluate: the estimated and true cameras differ in size; cannot compare their lenses");
  // Displacement of pixel uv by the camera's distortion: uv minus its undistorted pixel under the same K.
  const auto displacement = [](const core::Camera& c, const Eigen::Vector2d& uv) {
    const Eigen::Vector3d ray = c.Unproject(uv);
    const Eigen::Vector2d pin(c.fx() * ray.x() + c.u0, c.fy() * ray.y() + c.v0);
    return Eigen::Vector2d(uv - pin);
  };
  double worst = 0;
  for (const double u : {0.0, double(truth.width)})
    for (const double v : {0.0, double(truth.height)}) {
      const Eigen::Vector2d uv(u, v);
      worst = std::max(worst, (displacement(estimate, uv) - displacement(truth, uv)).norm());
    }
  return worst;
}

core::Sim3 AlignToTruth(const std::vector<Eigen::Vector3d>& ce, const std::vector<Eigen::Vector3d>& ct,
                        const std::vector<core::Pose>& pe, const std::vector<core::Pose>& pt, double extent,
                        AlignmentSource* from) {
  core::Sim3 by_centres;
  const bool centres_ok = geometry::EstimateSimilarity(ce, ct, &by_centres);
  *from = AlignmentSource::kCentres;
  if (centres_ok && geometry::Collinearity(ct) >= kCollinearTrack) return by_centres;
  // Each camera adds the point one extent ahead along its optical axis, at our scale: the centres' fit gives it, or
  // on an exact line the fit along that line.
  if (!centres_ok && !geometry::EstimateSimilarityAlongLine(ce, ct, &by_centres))
    throw Error("evaluate: camera centres have no spread, or none that matches the truth's; cannot align");
  const double scale = by_centres.s;
  std::vector<Eigen::Vector3d> src = ce, dst = ct;
  for (size_t i = 0; i < ce.size(); ++i) {
    src.push_back(ce[i] + extent / scale * pe[i].ViewDirection());
    dst.push_back(ct[i] + extent * pt[i].ViewDirection());
  }
  core::Sim3 sim;
  if (!geometry::EstimateSimilarity(src, dst, &sim))
    throw Error("evaluate: camera centres and viewing directions are degenerate; cannot align");
  *from = AlignmentSource::kCentresAndViewDirections;
  return sim;
}

SparseEvaluation EvaluateSparse(const core::Reconstruction& estimate, const core::Reconstruction& truth) {
  SparseEvaluation ev;
  ev.num_truth_images = static_cast<int>(truth.images.size());
  std::vector<Eigen::Vector3d> ce, ct;
  std::vector<core::Pose> pe, pt;
  std::map<uint32_t, uint32_t> camera_match;  // our camera → true camera
  for (const auto& [id, im] : estimate.images) {
    const core::Image* t = truth.FindImageByName(im.name);
    if (!t) continue;
    ce.push_back(im.pose.Centre());
    ct.push_back(t->pose.Centre());
    pe.push_back(im.pose);
    pt.push_back(t->pose);
    camera_match.emplace(im.camera_id, t->camera_id);
  }
  ev.num_matched = static_cast<int>(ce.size());
  if (ce.size() < 3)
    throw Error("evaluate: only " + std::to_string(ce.size()) +
                " registered images match ground-truth images by name (need ≥ 3)");
  for (size_t i = 0; i < ce.size(); ++i) {
    for (size_t j = i + 1; j < ct.size(); ++j) ev.extent = std::max(ev.extent, (ct[i] - ct[j]).norm());
  }
  ev.alignment = AlignToTruth(ce, ct, pe, pt, ev.extent, &ev.alignment_from);
  double sum = 0;
  for (size_t i = 0; i < ce.size(); ++i) {
    const double e = (ev.alignment.Apply(ce[i]) - ct[i]).norm();
    sum += e * e;
    ev.max_centre_error_fraction = std::max(ev.max_centre_error_fraction, e);
  }
  ev.centre_rmse = std::sqrt(sum / ce.size());
  ev.centre_rmse_fraction = ev.extent > 0 ? ev.centre_rmse / ev.extent : 0;
  ev.max_centre_error_fraction = ev.extent > 0 ? ev.max_centre_error_fraction / ev.extent : 0;
  ev.median_rotation_error_deg = MedianRelativeRotationErrorDeg(pe, pt);
  // A rotation error every camera shares in its own axes (e.g. all pitched alike) does not show in the relative
  // errors above, yet it moves the surface the views triangulate (on an orbit: up or down).
  Eigen::Vector3d sys = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < pe.size(); ++i) {
    // world-to-camera of ours in the truth's frame: R_est · q_align⁻¹
    const Eigen::Quaterniond aligned = pe[i].q * ev.alignment.q.conjugate();
    const Eigen::AngleAxisd d(pt[i].q * aligned.conjugate());  // camera-frame error rotation
    sys += d.angle() * d.axis();
  }
  ev.systematic_rotation_deg = sys / static_cast<double>(pe.size()) * 180.0 / M_PI;
  for (const auto& [ours, theirs] : camera_match) {
    const double fe = estimate.cameras.at(ours).f, ft = truth.cameras.at(theirs).f;
    if (ft > 0) ev.focal_relative_error = std::max(ev.focal_relative_error, std::abs(fe - ft) / ft);
    const auto& ce = estimate.cameras.at(ours);
    const auto& ct = truth.cameras.at(theirs);
    if (ct.fx() > 0)
      ev.focal_x_relative_error = std::max(ev.focal_x_relative_error, std::abs(ce.fx() - ct.fx()) / ct.fx());
    ev.principal_point_error_px = std::max(ev.principal_point_error_px, std::hypot(ce.u0 - ct.u0, ce.v0 - ct.v0));
    if (ce.width == ct.width && ce.height == ct.height)
      ev.lens_residual_corner_px = std::max(ev.lens_residual_corner_px, LensResidualPx(ce, ct));
  }
  return ev;
}

core::Reconstruction LoadTruth(const std::string& dir_str) {
  const fs::path dir(dir_str);
  if (!fs::is_directory(dir)) throw Error(dir_str + ": ground-truth folder not found");
  if (fs::exists(dir / "images.txt")) return io::ReadColmapText(dir);
  for (const auto& e : fs::directory_iterator(dir))
    if (e.path().extension() == ".camera") return io::ReadStrechaCameras(dir);
  throw Error(dir_str + ": no ground truth (neither a COLMAP text model nor Strecha NAME.camera files)");
}

SimilarityError CompareSimilarityToTruth(const core::Sim3& found, const SparseEvaluation& reference,
                                         const SparseEvaluation& moving, const Eigen::Vector3d& centre) {
  auto compose = [](const core::Sim3& a, const core::Sim3& b) {
    core::Sim3 c;
    c.s = a.s * b.s;
    c.q = a.q * b.q;
    c.t = a.s * (a.q * b.t) + a.t;
    return c;
  };
  const core::Sim3 E = compose(reference.alignment, compose(found, moving.alignment.Inverse()));
  SimilarityError e;
  e.rotation_deg = core::RotationAngle(E.q, Eigen::Quaterniond::Identity()) * 180 / M_PI;
  e.scale = std::abs(E.s - 1);
  e.translation_fraction = reference.extent > 0 ? (E.Apply(centre) - centre).norm() / reference.extent : 0;
  return e;
}

}  // namespace fmv3d::sfm
