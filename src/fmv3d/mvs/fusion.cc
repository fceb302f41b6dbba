#include "fmv3d/mvs/fusion.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>
#include <opencv2/imgproc.hpp>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/mvs/fusion_window.h"

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
  if (!(sigma_coverage > 0)) throw Error("fusion: sigma_coverage must be positive");
  if (!(texture_floor_quantile >= 0 && texture_floor_quantile < 1))
    throw Error("fusion: texture_floor_quantile must be in [0, 1)");
  if (!(sparse_tolerance >= 0 && sparse_tolerance < 1)) throw Error("fusion: sparse_tolerance must be in [0, 1)");
  if (sparse_min_votes < 1) throw Error("fusion: sparse_min_votes must be at least 1");
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
  const Eigen::Vector3d& ev = es.eigenvalues();  // ascending
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

FusionView MakeFusionView(const ViewGeometry& geom, const DepthMap& map, const cv::Mat& color,
                          std::vector<uint32_t> neighbours) {
  if (map.width() != geom.width || map.height() != geom.height || color.cols != geom.width || color.rows != geom.height)
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
      v.normal.at<Vec3s8>(y, x) =
          Vec3s8(static_cast<schar>(std::lround(127 * w.x())), static_cast<schar>(std::lround(127 * w.y())),
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

namespace {

// One fused point as it is emitted.
struct FusedPoint {
  Eigen::Vector3d position;
  Eigen::Vector3f normal;
  io::Rgb8 color;
  std::vector<uint32_t> visibility;
  int support = 0;
  float sigma = 0;          // σ_n (0 when neither the uncertainty filter nor the stated σ is on)
  float sigma_floored = 0;  // σ_n with p floored at the matching floor: what the stated σ is made of
  float footprint = 0;      // the reference pixel's footprint at the point (depth / focal), world units
  float scatter = -1;       // RMS spread of the consistent views' points along the normal (-1: fewer than 2)
};

// The fusion proper over the window's (eroded, surveyed) views, references in id order; every accepted point
// goes to emit(FusedPoint&&). `p_floor`: the matching floor of the pixel precision p (fusion.h), 0 for none.
void FuseMaps(FusionWindow& window, const FusionOptions& opt, double p_floor, FusionStats* st,
              const std::function<void(FusedPoint&&)>& emit) {
  const float cos_max = static_cast<float>(std::cos(opt.max_normal_error_deg * M_PI / 180));
  const double max_reproj2 = opt.max_reproj_error_px * opt.max_reproj_error_px;
  struct Hit {
    const FusionView* view;
    cv::Mat* used;
    int x, y;
    bool fresh;
  };
  std::vector<Hit> hits;
  const bool uncertainty = opt.max_relative_uncertainty > 0 || opt.write_sigma;
  st->texture_floor = p_floor;
  std::vector<const ViewGeometry*> hit_views;
  std::vector<double> hit_px;
  for (uint32_t rid : window.ids()) {
    // The reference and its neighbours are held (pinned in the window) while the reference is fused.
    const std::shared_ptr<FusionWindow::Slot> ref_slot = window.Get(rid);
    const FusionView& ref = ref_slot->view;
    std::vector<std::shared_ptr<FusionWindow::Slot>> nbs;
    for (uint32_t j : ref.neighbours)
      if (j != rid && window.Contains(j)) nbs.push_back(window.Get(j));
    cv::Mat& ref_used = ref_slot->used;
    for (int y = 0; y < ref.depth.rows; ++y) {
      for (int x = 0; x < ref.depth.cols; ++x) {
        const float d = ref.depth.at<float>(y, x);
        if (!(d > 0) || ref_used.at<uint8_t>(y, x)) continue;
        ++st->candidates;
        const Eigen::Vector3d X = ref.geom.Unproject({x + 0.5, y + 0.5}, d);
        const Eigen::Vector3f n_ref = NormalAt(ref, x, y);
        hits.clear();
        hits.push_back({&ref, &ref_used, x, y, true});
        int conflicts = 0;
        for (const auto& nb_slot : nbs) {
          const FusionView* nb = &nb_slot->view;
          Eigen::Vector2d uv;
          double z;
          if (!nb->geom.Project(X, &uv, &z)) continue;
          // Compared as doubles first: a point far outside the view projects beyond int's range.
          if (!(uv.x() >= 0 && uv.y() >= 0 && uv.x() < nb->depth.cols && uv.y() < nb->depth.rows)) continue;
          const int u = static_cast<int>(uv.x()), v = static_cast<int>(uv.y());
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
              hits.push_back({nb, &nb_slot->used, u, v, nb_slot->used.at<uint8_t>(v, u) == 0});
          } else if (rel > opt.visibility_margin) {
            ++conflicts;
          }
        }
        const int support = static_cast<int>(hits.size());
        if (support < opt.min_views) {
          ++st->rejected_support;
          continue;
        }
        if (opt.visibility_filter && conflicts > support - 1) {
          ++st->rejected_visibility;
          continue;
        }
        FusedPoint p;
        Eigen::Vector3d pos = Eigen::Vector3d::Zero();
        Eigen::Vector3f nrm = Eigen::Vector3f::Zero(), col = Eigen::Vector3f::Zero();
        int fresh = 0;
        p.visibility.reserve(hits.size());
        for (const Hit& h : hits) {
          p.visibility.push_back(h.view->geom.image_id);
          if (!h.fresh) continue;
          pos += h.view->geom.Unproject({h.x + 0.5, h.y + 0.5}, h.view->depth.at<float>(h.y, h.x));
          nrm += NormalAt(*h.view, h.x, h.y);
          const cv::Vec3b c = h.view->color.at<cv::Vec3b>(h.y, h.x);
          col += Eigen::Vector3f(c[2], c[1], c[0]);
          h.used->at<uint8_t>(h.y, h.x) = 1;
          ++fresh;
        }
        pos /= fresh;
        col /= static_cast<float>(fresh);
        if (nrm.norm() < 1e-6f) nrm = n_ref;
        p.position = pos;
        p.normal = nrm.normalized();
        if (fresh >= 2) {
          double s2 = 0;
          const Eigen::Vector3d n = p.normal.cast<double>();
          for (const Hit& h : hits)
            if (h.fresh)
              s2 += std::pow(
                  (h.view->geom.Unproject({h.x + 0.5, h.y + 0.5}, h.view->depth.at<float>(h.y, h.x)) - pos).dot(n), 2);
          p.scatter = static_cast<float>(std::sqrt(s2 / (fresh - 1)));
        }
        p.color = io::Rgb8(static_cast<uint8_t>(std::lround(col.x())), static_cast<uint8_t>(std::lround(col.y())),
                           static_cast<uint8_t>(std::lround(col.z())));
        p.support = support;
        if (uncertainty) {
          hit_views.clear();
          hit_px.clear();
          for (const Hit& h : hits) {
            hit_views.push_back(&h.view->geom);
            hit_px.push_back(
                h.view->texture.empty() ? 1.0 : static_cast<double>(h.view->texture.at<cv::float16_t>(h.y, h.x)));
          }
          p.sigma = static_cast<float>(NormalUncertainty(pos, p.normal.cast<double>(), hit_views, hit_px));
          p.sigma_floored = p.sigma;
          if (p_floor > 0) {
            for (double& px : hit_px) px = std::hypot(px, p_floor);
            p.sigma_floored = static_cast<float>(NormalUncertainty(pos, p.normal.cast<double>(), hit_views, hit_px));
          }
          p.footprint = static_cast<float>(d / (0.5 * (ref.geom.K(0, 0) + ref.geom.K(1, 1))));
        }
        emit(std::move(p));
      }
    }
  }
}

// σ_n in units of the reference pixel's footprint: how well the point is resolved for its distance (the
// triangulation angle and the texture), not how far it is.
std::vector<float> RelativeSigmas(const std::vector<float>& sigmas, const std::vector<float>& footprints) {
  std::vector<float> r(sigmas.size());
  for (size_t i = 0; i < sigmas.size(); ++i)
    r[i] = footprints[i] > 0 ? sigmas[i] / footprints[i] : std::numeric_limits<float>::infinity();
  return r;
}

// Sets the filter's median and threshold in *st from the points' footprint-relative σ_n.
void SetUncertaintyThreshold(std::vector<float> relative, const FusionOptions& opt, FusionStats* st) {
  if (!(opt.max_relative_uncertainty > 0) || relative.empty()) return;
  const size_t mid = relative.size() / 2;
  std::nth_element(relative.begin(), relative.begin() + static_cast<std::ptrdiff_t>(mid), relative.end());
  st->median_uncertainty = relative[mid];
  st->max_uncertainty = opt.max_relative_uncertainty * st->median_uncertainty;
}

// The scale that turns σ_n (pixel precision known up to a common factor) into world units: the median, over
// the points with a measured spread, of spread / σ_n (both along the normal).
double SigmaScale(const std::vector<float>& sigmas, const std::vector<float>& scatters) {
  std::vector<double> r;
  for (size_t i = 0; i < sigmas.size(); ++i)
    if (scatters[i] > 0 && sigmas[i] > 0 && std::isfinite(sigmas[i])) r.push_back(scatters[i] / sigmas[i]);
  if (r.empty()) return 0;
  std::nth_element(r.begin(), r.begin() + static_cast<std::ptrdiff_t>(r.size() / 2), r.end());
  return r[r.size() / 2];
}

float StatedSigma(float sigma_n, double scale, const FusionOptions& opt) {
  const double s = opt.sigma_coverage * scale * sigma_n;
  return std::isfinite(s) ? static_cast<float>(s) : std::numeric_limits<float>::max();
}

bool Keep(float relative_sigma, const FusionOptions& opt, const FusionStats& st) {
  return !(opt.max_relative_uncertainty > 0) || relative_sigma <= st.max_uncertainty;
}

}  // namespace

io::OrientedPointCloud FuseDepthMaps(const std::map<uint32_t, FusionView>& views, const FusionOptions& opt,
                                     FusionStats* stats) {
  opt.Check();
  FusionStats st;
  // Every view at once (nothing evicted), each with a copy of its depths: the erosion works in place.
  std::vector<uint32_t> ids;
  ids.reserve(views.size());
  for (const auto& [id, v] : views) ids.push_back(id);
  FusionWindow window(
      ids,
      [&views](uint32_t id) {
        FusionView v = views.at(id);
        v.depth = v.depth.clone();
        return v;
      },
      ids.size(), opt);
  const bool uncertainty = opt.max_relative_uncertainty > 0 || opt.write_sigma;
  window.Survey(&st, uncertainty && opt.texture_floor_quantile > 0);
  const double p_floor = uncertainty ? window.TextureQuantile(opt.texture_floor_quantile) : 0;
  io::OrientedPointCloud cloud;
  std::vector<int> support_of;
  std::vector<float> sigma_of, stated_of, scatter_of, footprint_of;
  FuseMaps(window, opt, p_floor, &st, [&](FusedPoint&& p) {
    cloud.positions.push_back(p.position);
    cloud.normals.push_back(p.normal);
    cloud.colors.push_back(p.color);
    cloud.visibility.push_back(std::move(p.visibility));
    support_of.push_back(p.support);
    sigma_of.push_back(p.sigma);
    stated_of.push_back(p.sigma_floored);
    scatter_of.push_back(p.scatter);
    footprint_of.push_back(p.footprint);
  });
  const std::vector<float> relative = RelativeSigmas(sigma_of, footprint_of);
  SetUncertaintyThreshold(relative, opt, &st);
  st.sigma_scale = opt.write_sigma ? SigmaScale(stated_of, scatter_of) : 0;
  if (opt.write_sigma) cloud.sigma.resize(cloud.size());
  // In place (no second copy of the cloud).
  size_t j = 0;
  for (size_t i = 0; i < cloud.size(); ++i) {
    if (!Keep(relative[i], opt, st)) {
      ++st.rejected_uncertainty;
      continue;
    }
    if (opt.write_sigma) cloud.sigma[j] = StatedSigma(stated_of[i], st.sigma_scale, opt);
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
  if (opt.write_sigma) cloud.sigma.resize(j);
  support_of.resize(j);
  for (int s : support_of) ++st.views_histogram[s];
  if (stats) *stats = st;
  return cloud;
}

size_t FuseDepthMapsToPly(std::map<uint32_t, FusionView> views, const FusionOptions& opt,
                          const std::filesystem::path& ply, FusionStats* stats) {
  std::vector<uint32_t> ids;
  ids.reserve(views.size());
  for (const auto& [id, v] : views) ids.push_back(id);
  // Every view at once: each is moved into the window once and never reloaded.
  FusionWindow window(
      ids, [&views](uint32_t id) { return std::move(views.at(id)); }, ids.size(), opt);
  return FuseDepthMapsToPly(window, opt, ply, stats);
}

size_t FuseDepthMapsToPly(FusionWindow& window, const FusionOptions& opt, const std::filesystem::path& ply,
                          FusionStats* stats) {
  opt.Check();
  FusionStats st;
  const bool uncertainty = opt.max_relative_uncertainty > 0 || opt.write_sigma;
  window.Survey(&st, uncertainty && opt.texture_floor_quantile > 0);
  const double p_floor = uncertainty ? window.TextureQuantile(opt.texture_floor_quantile) : 0;
  // Pass 1: every point's PLY record (float x y z, nx ny nz, uchar r g b, uchar n, n × int32 image id) to a
  // scratch file; only σ_n and the view count stay in memory.
  // A fixed name: a run killed here leaves it, and the resumed run overwrites and then removes it. Removed on
  // failure too (a full disk must not keep a half-written scratch file).
  const std::filesystem::path scratch = ply.string() + ".unfiltered";
  struct ScratchGuard {
    const std::filesystem::path& path;
    ~ScratchGuard() {
      std::error_code ec;
      std::filesystem::remove(path, ec);
    }
  } scratch_guard{scratch};
  std::vector<float> sigma_of, stated_of, scatter_of, footprint_of;
  std::vector<uint8_t> support_of;
  {
    std::ofstream out(scratch, std::ios::binary);
    if (!out) throw Error(scratch.string() + ": cannot write");
    std::string rec;
    FuseMaps(window, opt, p_floor, &st, [&](FusedPoint&& p) {
      rec.clear();
      auto put = [&](const void* d, size_t n) { rec.append(static_cast<const char*>(d), n); };
      const float xyz[3] = {static_cast<float>(p.position.x()), static_cast<float>(p.position.y()),
                            static_cast<float>(p.position.z())};
      put(xyz, sizeof xyz);
      put(p.normal.data(), 3 * sizeof(float));
      put(p.color.data(), 3);
      const uint8_t n = static_cast<uint8_t>(std::min<size_t>(p.visibility.size(), 255));
      put(&n, 1);
      for (int k = 0; k < n; ++k) {
        const int32_t id = static_cast<int32_t>(p.visibility[k]);
        put(&id, 4);
      }
      out.write(rec.data(), static_cast<std::streamsize>(rec.size()));
      sigma_of.push_back(p.sigma);
      stated_of.push_back(p.sigma_floored);
      scatter_of.push_back(p.scatter);
      footprint_of.push_back(p.footprint);
      support_of.push_back(static_cast<uint8_t>(std::min(p.support, 255)));
    });
    out.flush();
    if (!out) throw Error(scratch.string() + ": write failed (" + std::strerror(errno) + ")");
  }
  window.Release();
  const std::vector<float> relative = RelativeSigmas(sigma_of, footprint_of);
  footprint_of = {};
  SetUncertaintyThreshold(relative, opt, &st);
  st.sigma_scale = opt.write_sigma ? SigmaScale(stated_of, scatter_of) : 0;
  scatter_of = {};
  size_t kept = 0;
  for (size_t i = 0; i < sigma_of.size(); ++i)
    if (Keep(relative[i], opt, st)) ++kept, ++st.views_histogram[support_of[i]];
  st.rejected_uncertainty = sigma_of.size() - kept;
  // Pass 2: the kept records, behind the header of io::WritePointCloudPly's layout.
  core::WriteAtomically(ply, [&](const std::filesystem::path& tmp) {
    std::ifstream in(scratch, std::ios::binary);
    std::ofstream out(tmp, std::ios::binary);
    if (!in || !out) throw Error(tmp.string() + ": cannot write");
    out << "ply\nformat binary_little_endian 1.0\ncomment fmv3d oriented points\nelement vertex " << kept
        << "\nproperty float x\nproperty float y\nproperty float z\n"
        << "property float nx\nproperty float ny\nproperty float nz\n"
        << "property uchar red\nproperty uchar green\nproperty uchar blue\n"
        << (opt.write_sigma ? "property float sigma\n" : "") << "property list uchar int visibility\nend_header\n";
    constexpr size_t kFixed = 6 * sizeof(float) + 3 + 1;
    char rec[kFixed + size_t{255} * 4];  // up to 255 int32 visibility entries
    for (size_t i = 0; i < sigma_of.size(); ++i) {
      if (!in.read(rec, kFixed)) throw Error(scratch.string() + ": truncated");
      const size_t n = static_cast<uint8_t>(rec[kFixed - 1]);
      if (n > 0 && !in.read(rec + kFixed, static_cast<std::streamsize>(4 * n)))
        throw Error(scratch.string() + ": truncated");
      if (!Keep(relative[i], opt, st)) continue;
      if (opt.write_sigma) {  // between the colour and the visibility list, as io::WritePointCloudPly puts it
        out.write(rec, static_cast<std::streamsize>(kFixed - 1));
        const float sigma = StatedSigma(stated_of[i], st.sigma_scale, opt);
        out.write(reinterpret_cast<const char*>(&sigma), sizeof sigma);
        out.write(rec + kFixed - 1, static_cast<std::streamsize>(1 + 4 * n));
      } else {
        out.write(rec, static_cast<std::streamsize>(kFixed + 4 * n));
      }
    }
    if (!out) throw Error(tmp.string() + ": write failed");
  });

  if (stats) *stats = st;
  return kept;
}

}  // namespace fmv3d::mvs
