#include "fmv3d/mvs/fusion.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>

#include "fmv3d/core/error.h"

namespace fmv3d::mvs {

using Vec3s8 = cv::Vec<schar, 3>;

void FusionOptions::Check() const {
  if (min_views < 1) throw Error("fusion: min_views must be at least 1");
  if (!(max_depth_error > 0 && max_depth_error < 1)) throw Error("fusion: max_depth_error must be in (0, 1)");
  if (!(max_normal_error_deg > 0 && max_normal_error_deg <= 180))
    throw Error("fusion: max_normal_error_deg must be in (0, 180]");
  if (!(max_reproj_error_px > 0)) throw Error("fusion: max_reproj_error_px must be positive");
  if (!(visibility_margin > 0)) throw Error("fusion: visibility_margin must be positive");
  if (edge_erosion_px < 0) throw Error("fusion: edge_erosion_px must be >= 0");
  if (!(edge_depth_jump > 0)) throw Error("fusion: edge_depth_jump must be positive");
  if (!(max_relative_uncertainty == 0 || max_relative_uncertainty >= 1))
    throw Error("fusion: max_relative_uncertainty must be 0 (off) or at least 1");
}

double NormalUncertainty(const Eigen::Vector3d& X, const Eigen::Vector3d& n,
                         const std::vector<const ViewGeometry*>& views, const std::vector<double>& pixel_sigma) {
  constexpr double kMinCos = 0.05;  // rays within ~3° of the surface: footprint capped at 20 pixels' width
  Eigen::Matrix3d info = Eigen::Matrix3d::Zero();
  for (size_t i = 0; i < views.size(); ++i) {
    const ViewGeometry* g = views[i];
    const double z = (g->R * X + g->t).z();
    const double px = pixel_sigma.empty() ? 1.0 : pixel_sigma[i];
    if (!(z > 0) || !(px > 0) || !std::isfinite(px)) continue;
    const Eigen::Vector3d d = (X - g->Centre()).normalized();
    const double cos_t = std::max(kMinCos, std::abs(n.dot(d)));
    const double f = 0.5 * (g->K(0, 0) + g->K(1, 1));
    const double s = px * z / (f * cos_t);
    info += (Eigen::Matrix3d::Identity() - d * d.transpose()) / (s * s);
  }
  // Fewer than two distinct directions leave a null direction (along the common ray): unconstrained.
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(info);
  const Eigen::Vector3d ev = es.eigenvalues();  // ascending
  if (!(ev(2) > 0) || !(ev(0) > 1e-12 * ev(2))) return std::numeric_limits<double>::infinity();
  const Eigen::Vector3d c = es.eigenvectors().transpose() * n;
  return std::sqrt(c(0) * c(0) / ev(0) + c(1) * c(1) / ev(1) + c(2) * c(2) / ev(2));
}

cv::Mat TexturePrecisionMap(const cv::Mat& color, int radius_px) {
  CV_Assert(color.type() == CV_8UC3 && radius_px >= 1);
  cv::Mat grey, gx, gy;
  cv::cvtColor(color, grey, cv::COLOR_BGR2GRAY);
  grey.convertTo(grey, CV_32F, 1.0 / 255);
  cv::Sobel(grey, gx, CV_32F, 1, 0, 3, 1.0 / 8);  // grey levels per pixel
  cv::Sobel(grey, gy, CV_32F, 0, 1, 3, 1.0 / 8);
  const cv::Size window(2 * radius_px + 1, 2 * radius_px + 1);
  auto mean = [&](const cv::Mat& m) {
    cv::Mat out;
    cv::boxFilter(m, out, CV_32F, window, cv::Point(-1, -1), true, cv::BORDER_REFLECT);
    return out;
  };
  const cv::Mat mi = mean(grey), mii = mean(grey.mul(grey));
  const cv::Mat mx = mean(gx), mxx = mean(gx.mul(gx)), mxi = mean(gx.mul(grey));
  const cv::Mat my = mean(gy), myy = mean(gy.mul(gy)), myi = mean(gy.mul(grey));
  cv::Mat sigma(grey.size(), CV_32F);
  for (int y = 0; y < grey.rows; ++y)
    for (int x = 0; x < grey.cols; ++x) {
      const float vi = std::max(mii.at<float>(y, x) - mi.at<float>(y, x) * mi.at<float>(y, x), 0.f);
      // The part of each gradient component the gain/bias-invariant match can use: its variance over the
      // window less what a linear function of the intensity explains. (A shifted linear ramp is the same ramp
      // with another bias: NCC cannot see the shift, however steep the ramp.)
      auto usable = [&](const cv::Mat& m, const cv::Mat& mm, const cv::Mat& mg) {
        const float g = m.at<float>(y, x);
        const float var = std::max(mm.at<float>(y, x) - g * g, 0.f);
        const float cov = mg.at<float>(y, x) - g * mi.at<float>(y, x);
        return vi > 1e-12f ? std::max(var - cov * cov / vi, 0.f) : 0.f;
      };
      const float e = 0.5f * (usable(mx, mxx, mxi) + usable(my, myy, myi));
      sigma.at<float>(y, x) = std::min(6e4f, 1.f / std::sqrt(std::max(e, 1e-12f)));
    }
  cv::Mat half;
  sigma.convertTo(half, CV_16F);
  return half;
}

cv::Mat OccludingEdgeMask(const cv::Mat& depth, int radius_px, double depth_jump) {
  CV_Assert(depth.type() == CV_32F);
  cv::Mat mask = cv::Mat::zeros(depth.size(), CV_8U);
  if (radius_px <= 0) return mask;
  // The farthest depth within the radius (a disc): pixels without depth hold 0 and never win the max.
  cv::Mat farthest;
  const cv::Mat disc = cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * radius_px + 1, 2 * radius_px + 1));
  cv::dilate(depth, farthest, disc, cv::Point(-1, -1), 1, cv::BORDER_CONSTANT, cv::Scalar(0));
  const float k = static_cast<float>(1 + depth_jump);
  for (int y = 0; y < depth.rows; ++y) {
    const float* d = depth.ptr<float>(y);
    const float* f = farthest.ptr<float>(y);
    uint8_t* m = mask.ptr<uint8_t>(y);
    for (int x = 0; x < depth.cols; ++x)
      if (d[x] > 0 && f[x] > k * d[x]) m[x] = 255;
  }
  return mask;
}

FusionView MakeFusionView(const ViewGeometry& geom, const DepthMap& map, const cv::Mat& color,
                          std::vector<uint32_t> neighbours) {
  if (map.width() != geom.width || map.height() != geom.height || color.cols != geom.width ||
      color.rows != geom.height)
    throw Error("fusion: depth map of '" + geom.name + "' does not match its view's size");
  FusionView v;
  v.geom = geom;
  v.depth = map.depth.clone();
  v.color = color;
  v.neighbours = std::move(neighbours);
  v.normal.create(map.height(), map.width(), CV_8SC3);
  const Eigen::Matrix3f Rt = geom.R.transpose().cast<float>();
  for (int y = 0; y < map.height(); ++y)
    for (int x = 0; x < map.width(); ++x) {
      const cv::Vec3f n = map.normal.at<cv::Vec3f>(y, x);
      const Eigen::Vector3f w = Rt * Eigen::Vector3f(n[0], n[1], n[2]);
      v.normal.at<Vec3s8>(y, x) = Vec3s8(static_cast<schar>(std::lround(127 * w.x())),
                                         static_cast<schar>(std::lround(127 * w.y())),
                                         static_cast<schar>(std::lround(127 * w.z())));
    }
  return v;
}

namespace {
Eigen::Vector3f NormalAt(const FusionView& v, int x, int y) {
  const Vec3s8 c = v.normal.at<Vec3s8>(y, x);
  return Eigen::Vector3f(c[0], c[1], c[2]).normalized();
}
}  // namespace

io::OrientedPointCloud FuseDepthMaps(const std::map<uint32_t, FusionView>& views, const FusionOptions& opt,
                                     FusionStats* stats) {
  opt.Check();
  FusionStats st;
  io::OrientedPointCloud cloud;
  // Depths with the occluding edges' foreground side removed (a copy only when something is removed).
  std::map<uint32_t, FusionView> eroded;
  const std::map<uint32_t, FusionView>* maps = &views;
  if (opt.edge_erosion_px > 0) {
    for (const auto& [id, v] : views) {
      FusionView e = v;
      const cv::Mat mask = OccludingEdgeMask(v.depth, opt.edge_erosion_px, opt.edge_depth_jump);
      st.edge_pixels += static_cast<size_t>(cv::countNonZero(mask));
      e.depth = v.depth.clone();
      e.depth.setTo(0, mask);
      eroded.emplace(id, std::move(e));
    }
    maps = &eroded;
  }
  std::map<uint32_t, cv::Mat> used;
  for (const auto& [id, v] : *maps) used[id] = cv::Mat::zeros(v.depth.size(), CV_8U);
  const float cos_max = static_cast<float>(std::cos(opt.max_normal_error_deg * M_PI / 180));
  const double max_reproj2 = opt.max_reproj_error_px * opt.max_reproj_error_px;

  struct Hit {
    const FusionView* view;
    int x, y;
    bool fresh;
  };
  std::vector<Hit> hits;
  std::vector<int> support_of;   // per fused point
  std::vector<float> sigma_of;  // per fused point: σ_n (only with the uncertainty filter)
  const bool uncertainty = opt.max_relative_uncertainty > 0;
  std::vector<const ViewGeometry*> hit_views;
  std::vector<double> hit_px;
  for (const auto& [rid, ref] : *maps) {
    std::vector<const FusionView*> nbs;
    for (uint32_t j : ref.neighbours) {
      auto it = maps->find(j);
      if (it != maps->end() && j != rid) nbs.push_back(&it->second);
    }
    cv::Mat& ref_used = used[rid];
    for (int y = 0; y < ref.depth.rows; ++y) {
      for (int x = 0; x < ref.depth.cols; ++x) {
        const float d = ref.depth.at<float>(y, x);
        if (!(d > 0) || ref_used.at<uint8_t>(y, x)) continue;
        ++st.candidates;
        const Eigen::Vector3d X = ref.geom.Unproject({x + 0.5, y + 0.5}, d);
        const Eigen::Vector3f n_ref = NormalAt(ref, x, y);
        hits.clear();
        hits.push_back({&ref, x, y, true});
        int conflicts = 0;
        for (const FusionView* nb : nbs) {
          Eigen::Vector2d uv;
          double z;
          if (!nb->geom.Project(X, &uv, &z)) continue;
          const int u = static_cast<int>(std::floor(uv.x())), v = static_cast<int>(std::floor(uv.y()));
          if (u < 0 || v < 0 || u >= nb->depth.cols || v >= nb->depth.rows) continue;
          const float dj = nb->depth.at<float>(v, u);
          if (!(dj > 0)) continue;
          const double rel = (dj - z) / z;
          if (std::abs(rel) <= opt.max_depth_error) {
            // j's surface point on the same ray, seen from the reference.
            Eigen::Vector2d back;
            if (!ref.geom.Project(nb->geom.Unproject(uv, dj), &back) ||
                (back - Eigen::Vector2d(x + 0.5, y + 0.5)).squaredNorm() > max_reproj2)
              continue;
            if (NormalAt(*nb, u, v).dot(n_ref) >= cos_max)
              hits.push_back({nb, u, v, used[nb->geom.image_id].at<uint8_t>(v, u) == 0});
          } else if (rel > opt.visibility_margin) {
            ++conflicts;
          }
        }
        const int support = static_cast<int>(hits.size());
        if (support < opt.min_views) {
          ++st.rejected_support;
          continue;
        }
        if (opt.visibility_filter && conflicts > support - 1) {
          ++st.rejected_visibility;
          continue;
        }
        Eigen::Vector3d pos = Eigen::Vector3d::Zero();
        Eigen::Vector3f nrm = Eigen::Vector3f::Zero(), col = Eigen::Vector3f::Zero();
        int fresh = 0;
        std::vector<uint32_t> vis;
        vis.reserve(hits.size());
        for (const Hit& h : hits) {
          vis.push_back(h.view->geom.image_id);
          if (!h.fresh) continue;
          pos += h.view->geom.Unproject({h.x + 0.5, h.y + 0.5}, h.view->depth.at<float>(h.y, h.x));
          nrm += NormalAt(*h.view, h.x, h.y);
          const cv::Vec3b c = h.view->color.at<cv::Vec3b>(h.y, h.x);
          col += Eigen::Vector3f(c[2], c[1], c[0]);
          used[h.view->geom.image_id].at<uint8_t>(h.y, h.x) = 1;
          ++fresh;
        }
        pos /= fresh;
        col /= static_cast<float>(fresh);
        if (nrm.norm() < 1e-6f) nrm = n_ref;
        cloud.positions.push_back(pos);
        cloud.normals.push_back(nrm.normalized());
        cloud.colors.push_back(io::Rgb8(static_cast<uint8_t>(std::lround(col.x())),
                                        static_cast<uint8_t>(std::lround(col.y())),
                                        static_cast<uint8_t>(std::lround(col.z()))));
        cloud.visibility.push_back(std::move(vis));
        support_of.push_back(support);
        if (uncertainty) {
          hit_views.clear();
          hit_px.clear();
          for (const Hit& h : hits) {
            hit_views.push_back(&h.view->geom);
            hit_px.push_back(h.view->texture.empty() ? 1.0
                                                     : static_cast<double>(h.view->texture.at<cv::float16_t>(h.y, h.x)));
          }
          sigma_of.push_back(static_cast<float>(
              NormalUncertainty(pos, cloud.normals.back().cast<double>(), hit_views, hit_px)));
        }
      }
    }
  }
  if (uncertainty && !cloud.empty()) {
    std::vector<float> sorted = sigma_of;
    const size_t mid = sorted.size() / 2;
    std::nth_element(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(mid), sorted.end());
    st.median_uncertainty = sorted[mid];
    st.max_uncertainty = opt.max_relative_uncertainty * st.median_uncertainty;
    // In place (no second copy of the cloud).
    size_t j = 0;
    for (size_t i = 0; i < cloud.size(); ++i) {
      if (!(sigma_of[i] <= st.max_uncertainty)) {
        ++st.rejected_uncertainty;
        continue;
      }
      if (j != i) {
        cloud.positions[j] = cloud.positions[i];
        cloud.normals[j] = cloud.normals[i];
        cloud.colors[j] = cloud.colors[i];
        cloud.visibility[j] = std::move(cloud.visibility[i]);
        support_of[j] = support_of[i];
      }
      ++j;
    }
    cloud.positions.resize(j);
    cloud.normals.resize(j);
    cloud.colors.resize(j);
    cloud.visibility.resize(j);
    support_of.resize(j);
  }
  for (int s : support_of) ++st.views_histogram[s];
  if (stats) *stats = st;
  return cloud;
}

}  // namespace fmv3d::mvs
