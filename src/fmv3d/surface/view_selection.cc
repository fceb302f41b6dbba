#include "fmv3d/surface/view_selection.h"

#include <spdlog/spdlog.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <numeric>

#include "fmv3d/core/error.h"
#include "fmv3d/core/logging.h"
#include "fmv3d/render/renderer.h"

namespace fmv3d::surface {
namespace {

using Clock = std::chrono::steady_clock;

// 12 bytes: a long video's mesh has millions of faces, each seen by tens of views (61 views of a 7.7 M-face mesh:
// 209 M candidates, 10 GB at the former 24 bytes and two copies).
struct Candidate {
  float quality;
  uint16_t view;
  std::array<uint8_t, 3> color;  // BGR mean over the face's pixels, rounded
  Eigen::Vector3f Color() const { return {color[0], color[1], color[2]}; }
};

// Per face, the `k` best candidates by quality (a fixed slot array; faces are only ever touched by one thread).
class CandidateStore {
 public:
  CandidateStore(size_t faces, int k) : k_(k), slots_(faces * k), count_(faces, 0) {}
  void Offer(size_t f, const Candidate& c) {
    Candidate* s = &slots_[f * k_];
    if (count_[f] < k_) {
      s[count_[f]++] = c;
      return;
    }
    int worst = 0;
    for (int i = 1; i < k_; ++i)
      if (s[i].quality < s[worst].quality) worst = i;
    if (c.quality > s[worst].quality) s[worst] = c;
  }
  // Into CSR form ordered by view within each face, in place (a face's CSR start never passes its slots).
  void ToCsr(std::vector<size_t>* offset, std::vector<Candidate>* out) {
    const size_t nf = count_.size();
    offset->assign(nf + 1, 0);
    for (size_t f = 0; f < nf; ++f) (*offset)[f + 1] = (*offset)[f] + count_[f];
    for (size_t f = 0; f < nf; ++f) {
      Candidate* s = &slots_[f * k_];
      std::sort(s, s + count_[f], [](const Candidate& a, const Candidate& b) { return a.view < b.view; });
      std::copy(s, s + count_[f], slots_.begin() + (*offset)[f]);
    }
    slots_.resize((*offset)[nf]);
    slots_.shrink_to_fit();
    *out = std::move(slots_);
  }

 private:
  int k_;
  std::vector<Candidate> slots_;
  std::vector<uint8_t> count_;
};

std::array<uint8_t, 3> Rounded(const Eigen::Vector3f& c) {
  std::array<uint8_t, 3> out;
  for (int k = 0; k < 3; ++k) out[k] = static_cast<uint8_t>(std::clamp(std::lround(c[k]), 0L, 255L));
  return out;
}

// Bilinear BGR colour at a continuous pixel position (pixel centres at +0.5), clamped to the image.
Eigen::Vector3f SampleBilinear(const cv::Mat& img, double u, double v) {
  const double x = std::clamp(u - 0.5, 0.0, img.cols - 1.0), y = std::clamp(v - 0.5, 0.0, img.rows - 1.0);
  const int x0 = static_cast<int>(x), y0 = static_cast<int>(y);
  const int x1 = std::min(x0 + 1, img.cols - 1), y1 = std::min(y0 + 1, img.rows - 1);
  const float ax = static_cast<float>(x - x0), ay = static_cast<float>(y - y0);
  Eigen::Vector3f c = Eigen::Vector3f::Zero();
  const auto add = [&](int xx, int yy, float w) {
    const cv::Vec3b& p = img.at<cv::Vec3b>(yy, xx);
    c += w * Eigen::Vector3f(p[0], p[1], p[2]);
  };
  add(x0, y0, (1 - ax) * (1 - ay));
  add(x1, y0, ax * (1 - ay));
  add(x0, y1, (1 - ax) * ay);
  add(x1, y1, ax * ay);
  return c;
}

// The candidates of one view, offered to the store.
void ViewCandidates(const ColoredMesh& mesh, const std::vector<Eigen::Vector3d>& face_normals,
                    const render::Renderer& renderer, const TextureView& view, const cv::Mat& image, int view_index,
                    const ViewSelectionOptions& options, CandidateStore* store) {
  const core::Camera& cam = view.camera;
  const double s = options.visibility_scale;
  core::Camera small = cam;
  small.width = std::max(1, static_cast<int>(std::lround(cam.width * s)));
  small.height = std::max(1, static_cast<int>(std::lround(cam.height * s)));
  const double sx = static_cast<double>(small.width) / cam.width, sy = static_cast<double>(small.height) / cam.height;
  small.f = cam.f * sy;
  small.aspect = cam.aspect * sx / sy;
  small.u0 = cam.u0 * sx;
  small.v0 = cam.v0 * sy;
  render::RenderOptions ro;
  ro.supersample = 1;
  ro.shading = false;
  ro.cull_backfaces = true;
  const render::RenderResult r = renderer.Render(small, view.pose, ro);

  // Pixel counts and colour sums of every face the raster shows.
  const size_t nf = mesh.triangles.size();
  std::vector<int> count(nf, 0);
  std::vector<Eigen::Vector3f> sum(nf, Eigen::Vector3f::Zero());
  for (int y = 0; y < small.height; ++y) {
    const int32_t* fr = r.face.ptr<int32_t>(y);
    const int iy = std::min(cam.height - 1, static_cast<int>((y + 0.5) / sy));
    const cv::Vec3b* ir = image.ptr<cv::Vec3b>(iy);
    for (int x = 0; x < small.width; ++x) {
      const int f = fr[x];
      if (f < 0) continue;
      const cv::Vec3b& p = ir[std::min(cam.width - 1, static_cast<int>((x + 0.5) / sx))];
      ++count[f];
      sum[f] += Eigen::Vector3f(p[0], p[1], p[2]);
    }
  }

  const double min_cos = std::cos(options.max_angle_deg * M_PI / 180.0);
  const Eigen::Vector3d centre = view.pose.Centre();
  constexpr size_t kChunks = 64;  // chunks of faces: each face is offered by one thread only
  tbb::parallel_for(size_t{0}, kChunks, [&](size_t c) {
    const size_t begin = nf * c / kChunks, end = nf * (c + 1) / kChunks;
    for (size_t f = begin; f < end; ++f) {
      const auto& t = mesh.triangles[f];
      const Eigen::Vector3d centroid = (mesh.vertices[t[0]] + mesh.vertices[t[1]] + mesh.vertices[t[2]]) / 3.0;
      const Eigen::Vector3d to_cam = centre - centroid;
      const double dist = to_cam.norm();
      if (!(dist > 0) || face_normals[f].dot(to_cam) < min_cos * dist) continue;
      Eigen::Vector2d uv[3];
      bool inside = true;
      for (int k = 0; k < 3 && inside; ++k) {
        const Eigen::Vector3d x = view.pose.Transform(mesh.vertices[t[k]]);
        inside = x.z() > 0 && cam.InImage(uv[k] = cam.Project(x), 0.5);
      }
      if (!inside) continue;
      const double area =
          0.5 * std::abs((uv[1] - uv[0]).x() * (uv[2] - uv[0]).y() - (uv[1] - uv[0]).y() * (uv[2] - uv[0]).x());
      const double area_small = area * sx * sy;
      Candidate cand{static_cast<float>(area), static_cast<uint16_t>(view_index), {0, 0, 0}};
      if (count[f] > 0) {
        cand.color = Rounded(sum[f] / static_cast<float>(count[f]));
        // Partly hidden faces show fewer pixels than their projected area (small faces' counts are too noisy).
        if (area_small >= 8) cand.quality *= static_cast<float>(std::min(1.0, count[f] / area_small));
      } else {
        if (area_small >= 2) continue;  // a face of several pixels that shows none is hidden
        // Sub-pixel face: depth test of its centroid against the rendered surface.
        const Eigen::Vector3d xc = view.pose.Transform(centroid);
        const Eigen::Vector2d pc = small.Project(xc);
        const int px = std::clamp(static_cast<int>(pc.x()), 0, small.width - 1);
        const int py = std::clamp(static_cast<int>(pc.y()), 0, small.height - 1);
        const float d = r.depth.at<float>(py, px);
        const double footprint = xc.z() / small.f;
        if (!(d > 0) || std::abs(xc.z() - d) > 0.01 * xc.z() + 3 * footprint) continue;
        const Eigen::Vector2d pf = cam.Project(xc);
        cand.color = Rounded(SampleBilinear(image, pf.x(), pf.y()));
      }
      store->Offer(f, cand);
    }
  });
}

}  // namespace

void ViewSelectionOptions::Check() const {
  if (!(max_angle_deg > 0 && max_angle_deg < 90)) throw Error("texture: max view angle must be in (0, 90) degrees");
  if (!(consistency_threshold > 0)) throw Error("texture: consistency threshold must be positive");
  if (!(smoothness >= 0)) throw Error("texture: smoothness must be >= 0");
  if (smoothing_iterations < 0) throw Error("texture: smoothing iterations must be >= 0");
  if (!(visibility_scale > 0 && visibility_scale <= 1)) throw Error("texture: visibility scale must be in (0, 1]");
  if (max_candidates_per_face < 1 || max_candidates_per_face > 255)
    throw Error("texture: max candidates per face must be in [1, 255]");
}

std::vector<Eigen::Vector3i> FaceAdjacency(const std::vector<Eigen::Vector3i>& triangles) {
  struct HalfEdge {
    int a, b, face, slot;
  };
  std::vector<HalfEdge> edges;
  edges.reserve(triangles.size() * 3);
  for (size_t f = 0; f < triangles.size(); ++f)
    for (int k = 0; k < 3; ++k) {
      const int a = triangles[f][k], b = triangles[f][(k + 1) % 3];
      edges.push_back({std::min(a, b), std::max(a, b), static_cast<int>(f), k});
    }
  std::sort(edges.begin(), edges.end(), [](const HalfEdge& x, const HalfEdge& y) {
    return x.a != y.a ? x.a < y.a : x.b != y.b ? x.b < y.b : x.face < y.face;
  });
  std::vector<Eigen::Vector3i> adj(triangles.size(), Eigen::Vector3i::Constant(-1));
  for (size_t i = 0; i < edges.size();) {
    size_t j = i;
    while (j < edges.size() && edges[j].a == edges[i].a && edges[j].b == edges[i].b) ++j;
    if (j - i == 2) {  // manifold edge: exactly two faces
      adj[edges[i].face][edges[i].slot] = edges[i + 1].face;
      adj[edges[i + 1].face][edges[i + 1].slot] = edges[i].face;
    }
    i = j;
  }
  return adj;
}

namespace {

// Every view's candidates per face (the best max_candidates_per_face by quality), in CSR form ordered by view:
// face f's candidates are cand[offset[f] .. offset[f + 1]).
struct FaceCandidates {
  std::vector<size_t> offset;
  std::vector<Candidate> cand;
  const Candidate* Find(int f, int view) const {  // a handful of candidates per face
    for (size_t i = offset[f]; i < offset[f + 1]; ++i)
      if (cand[i].view == view) return &cand[i];
    return nullptr;
  }
};

FaceCandidates CollectCandidates(const ColoredMesh& mesh, const std::vector<TextureView>& views, FrameWindow& frames,
                                 const ViewSelectionOptions& options) {
  const size_t nf = mesh.triangles.size();
  const io::TexturedMesh geometry = mesh.ToTexturedMesh();
  const render::Renderer renderer(geometry);
  std::vector<Eigen::Vector3d> face_normals(nf);
  for (size_t f = 0; f < nf; ++f) face_normals[f] = geometry.FaceNormal(f);
  FaceCandidates fc;
  CandidateStore store(nf, options.max_candidates_per_face);
  core::Progress progress("texture: visibility", views.size());
  // In ascending view order: the store keeps the first offered of equal-quality candidates.
  std::vector<size_t> all(views.size());
  std::iota(all.begin(), all.end(), size_t{0});
  frames.ForEach(
      all,
      [&](size_t v, const cv::Mat& image) {
        ViewCandidates(mesh, face_normals, renderer, views[v], image, static_cast<int>(v), options, &store);
        progress.Add();
      },
      /*ascending=*/true);
  store.ToCsr(&fc.offset, &fc.cand);
  return fc;
}

// Photo-consistency on neighbourhood-averaged colours: per face, candidates whose colour lies far from the
// candidates' median (beyond the threshold and 3 median deviations) are marked inconsistent (0).
std::vector<char> ConsistentCandidates(const FaceCandidates& fc, const std::vector<Eigen::Vector3i>& adjacency,
                                       size_t nf, const ViewSelectionOptions& options, size_t* rejected) {
  std::vector<char> consistent(fc.cand.size(), 1);
  std::vector<size_t> rejected_per_chunk(64, 0);
  tbb::parallel_for(size_t{0}, size_t{64}, [&](size_t chunk) {
    std::vector<Eigen::Vector3f> colors;
    std::vector<float> channel, dist;
    for (size_t f = nf * chunk / 64; f < nf * (chunk + 1) / 64; ++f) {
      const size_t n = fc.offset[f + 1] - fc.offset[f];
      if (n < 3) continue;
      colors.clear();
      for (size_t i = fc.offset[f]; i < fc.offset[f + 1]; ++i) {
        Eigen::Vector3f c = fc.cand[i].Color();
        int m = 1;
        for (int k = 0; k < 3; ++k)
          if (adjacency[f][k] >= 0)
            if (const Candidate* o = fc.Find(adjacency[f][k], fc.cand[i].view)) c += o->Color(), ++m;
        colors.push_back(c / static_cast<float>(m));
      }
      Eigen::Vector3f median;
      for (int ch = 0; ch < 3; ++ch) {
        channel.clear();
        for (const auto& c : colors) channel.push_back(c[ch]);
        std::nth_element(channel.begin(), channel.begin() + n / 2, channel.end());
        median[ch] = channel[n / 2];
      }
      dist.clear();
      for (const auto& c : colors) dist.push_back((c - median).norm());
      std::vector<float> sorted = dist;
      std::nth_element(sorted.begin(), sorted.begin() + n / 2, sorted.end());
      const float limit = std::max(static_cast<float>(options.consistency_threshold), 3.0f * sorted[n / 2]);
      for (size_t k = 0; k < n; ++k)
        if (dist[k] > limit) {
          consistent[fc.offset[f] + k] = 0;
          ++rejected_per_chunk[chunk];
        }
    }
  });
  *rejected = 0;
  for (size_t r : rejected_per_chunk) *rejected += r;
  return consistent;
}

// Labels: the best consistent candidate per face, then label voting (Gauss–Seidel sweeps in face order:
// deterministic, and converges in a few sweeps). Returns the number of changes per sweep.
std::vector<size_t> LabelFaces(const FaceCandidates& fc, const std::vector<char>& consistent,
                               const std::vector<Eigen::Vector3i>& adjacency, const ViewSelectionOptions& options,
                               std::vector<int>& labels) {
  const size_t nf = labels.size();
  std::vector<float> best_quality(nf, 0);
  for (size_t f = 0; f < nf; ++f)
    for (size_t i = fc.offset[f]; i < fc.offset[f + 1]; ++i)
      if (consistent[i] && fc.cand[i].quality > best_quality[f]) {
        best_quality[f] = fc.cand[i].quality;
        labels[f] = fc.cand[i].view;
      }
  std::vector<size_t> changes;
  for (int it = 0; it < options.smoothing_iterations && options.smoothness > 0; ++it) {
    size_t changed = 0;
    for (size_t f = 0; f < nf; ++f) {
      if (labels[f] < 0) continue;
      double best = -1;
      int best_view = labels[f];
      for (size_t i = fc.offset[f]; i < fc.offset[f + 1]; ++i) {
        if (!consistent[i]) continue;
        int agree = 0;
        for (int k = 0; k < 3; ++k) agree += adjacency[f][k] >= 0 && labels[adjacency[f][k]] == fc.cand[i].view;
        const double score = fc.cand[i].quality / best_quality[f] + options.smoothness * agree;
        if (score > best + 1e-12) {
          best = score;
          best_view = fc.cand[i].view;
        }
      }
      if (best_view != labels[f]) {
        labels[f] = best_view;
        ++changed;
      }
    }
    changes.push_back(changed);
    if (changed == 0) break;
  }
  return changes;
}

}  // namespace

ViewSelection SelectViews(const ColoredMesh& mesh, const std::vector<Eigen::Vector3i>& adjacency,
                          const std::vector<TextureView>& views, FrameWindow& frames,
                          const ViewSelectionOptions& options) {
  options.Check();
  const auto start = Clock::now();
  const size_t nf = mesh.triangles.size();
  ViewSelection result;
  result.labels.assign(nf, -1);
  if (nf == 0 || views.empty()) return result;
  if (views.size() > 65535) throw Error("texture: at most 65535 views");

  const FaceCandidates fc = CollectCandidates(mesh, views, frames, options);
  const double seconds_visibility = std::chrono::duration<double>(Clock::now() - start).count();
  size_t rejected = 0;
  const std::vector<char> consistent = ConsistentCandidates(fc, adjacency, nf, options, &rejected);
  std::vector<size_t> changes = LabelFaces(fc, consistent, adjacency, options, result.labels);

  size_t labelled = 0;
  for (int l : result.labels) labelled += l >= 0;
  auto& st = result.stats;
  st.faces = nf;
  st.views = views.size();
  st.candidates = fc.cand.size();
  st.mean_candidates_per_face = static_cast<double>(fc.cand.size()) / nf;
  st.inconsistent_candidates = rejected;
  st.labelled_faces = labelled;
  st.labelled_share = static_cast<double>(labelled) / nf;
  st.smoothing_changes = std::move(changes);
  st.seconds_visibility = seconds_visibility;
  st.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  spdlog::info("texture: {} of {} faces seen ({:.1f} candidate views per face, {} inconsistent dropped)", labelled, nf,
               st.mean_candidates_per_face, rejected);
  return result;
}

}  // namespace fmv3d::surface
