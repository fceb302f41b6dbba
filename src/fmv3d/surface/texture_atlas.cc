#include "fmv3d/surface/texture_atlas.h"

#include <spdlog/spdlog.h>
#include <tbb/parallel_for.h>

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numeric>
#include <opencv2/imgproc.hpp>
#include <unordered_map>

#include "fmv3d/core/error.h"

namespace fmv3d::surface {
namespace {

struct UnionFind {
  std::vector<int> parent;
  explicit UnionFind(size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), 0); }
  int Find(int x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  }
  void Union(int a, int b) {
    a = Find(a), b = Find(b);
    if (a != b) parent[std::max(a, b)] = std::min(a, b);  // smallest root: deterministic
  }
};

// A rectangle of source pixels [x0, x1) × [y0, y1) of one view (or a flat block for unseen faces) and where
// it lands in the atlas.
struct Chart {
  int view = -1;  // -1: flat block of unseen faces
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  double scale = 1;  // texels per source pixel
  int w = 0, h = 0;  // size in the atlas, texels
  int page = -1, px = 0, py = 0;
  Eigen::Vector3f flat_bgr = Eigen::Vector3f::Zero();
};

Eigen::Vector3f Bilinear(const cv::Mat& img, double u, double v) {
  const double x = std::clamp(u - 0.5, 0.0, img.cols - 1.0), y = std::clamp(v - 0.5, 0.0, img.rows - 1.0);
  const int x0 = static_cast<int>(x), y0 = static_cast<int>(y);
  const int x1 = std::min(x0 + 1, img.cols - 1), y1 = std::min(y0 + 1, img.rows - 1);
  const float ax = static_cast<float>(x - x0), ay = static_cast<float>(y - y0);
  const auto px = [&](int xx, int yy) {
    const cv::Vec3b& p = img.at<cv::Vec3b>(yy, xx);
    return Eigen::Vector3f(p[0], p[1], p[2]);
  };
  return (1 - ay) * ((1 - ax) * px(x0, y0) + ax * px(x1, y0)) + ay * ((1 - ax) * px(x0, y1) + ax * px(x1, y1));
}

int NextPow2(int v) {
  int p = 1;
  while (p < v) p <<= 1;
  return p;
}

// Copies image pixels [x0, x1) × [y0, y1) (the rectangle may reach past the border: edge pixels repeat),
// resized to w × h, into dst at (px, py).
void CopyChart(const cv::Mat& image, const Chart& c, cv::Mat* dst) {
  const cv::Rect want(c.x0, c.y0, c.x1 - c.x0, c.y1 - c.y0);
  const cv::Rect have = want & cv::Rect(0, 0, image.cols, image.rows);
  cv::Mat region;
  if (have.area() == 0) {
    region = cv::Mat(want.size(), CV_8UC3, cv::Scalar(0, 0, 0));
  } else {
    cv::copyMakeBorder(image(have), region, have.y - want.y, want.br().y - have.br().y, have.x - want.x,
                       want.br().x - have.br().x, cv::BORDER_REPLICATE);
  }
  if (region.cols != c.w || region.rows != c.h) cv::resize(region, region, cv::Size(c.w, c.h), 0, 0, cv::INTER_AREA);
  region.copyTo((*dst)(cv::Rect(c.px, c.py, c.w, c.h)));
}

// Multiplies a copied chart by its view's per-channel gain (on a continuous copy of the texels, as the product
// was taken before the chart was placed).
void ApplyGain(const Chart& c, const Eigen::Vector3f& gain, cv::Mat* dst) {
  if (!(gain.array() != 1.0f).any()) return;
  const cv::Rect where(c.px, c.py, c.w, c.h);
  cv::Mat region = (*dst)(where).clone();
  cv::multiply(region, cv::Scalar(gain[0], gain[1], gain[2]), region);
  region.copyTo((*dst)(where));
}

}  // namespace

void AtlasOptions::Check() const {
  if (max_page_size < 256 || max_page_size > 16384 || (max_page_size & (max_page_size - 1)))
    throw Error("texture: atlas page size must be a power of two in 256..16384");
  if (margin < 0 || margin > 64) throw Error("texture: chart margin must be in 0..64 texels");
  if (!(texel_scale > 0 && texel_scale <= 4)) throw Error("texture: texel scale must be in (0, 4]");
  if (!(gain_regularisation > 0)) throw Error("texture: gain regularisation must be positive");
}

namespace {

// 2. Per-view colour gains from the seams (log colour: a gain is an offset there). Each seam edge is sampled at
// three points in both views; the samples' colours are read view by view in the atlas's pass over the frame
// window, then summed in face order (the same sums, to the bit, whatever the window holds).
class SeamSamples {
 public:
  SeamSamples(const ColoredMesh& mesh, const std::vector<Eigen::Vector3i>& adjacency, const std::vector<int>& labels,
              size_t num_views, const AtlasOptions& options)
      : mesh_(mesh), adjacency_(adjacency), labels_(labels), reads_of_view_(num_views) {
    if (!options.adjust_colors || num_views < 2) return;
    for (size_t f = 0; f < mesh.triangles.size(); ++f)
      for (int k = 0; k < 3; ++k) {
        const int g = adjacency[f][k];
        if (g <= static_cast<int>(f) || labels[f] < 0 || labels[g] < 0 || labels[g] == labels[f]) continue;
        ++seam_edges_;
        for (uint8_t step = 0; step < 3; ++step)
          samples_.push_back({static_cast<uint32_t>(f), static_cast<uint8_t>(k), step});
      }
    for (size_t r = 0; r < 2 * samples_.size(); ++r) reads_of_view_[ViewOf(r)].push_back(r);
    colour_.resize(2 * samples_.size());
  }
  size_t seam_edges() const { return seam_edges_; }
  bool Reads(size_t view) const { return !reads_of_view_[view].empty(); }
  // The colours of the samples seen in `view`, from its pixels.
  void Read(size_t view, const TextureView& v, const cv::Mat& image) {
    std::vector<size_t>& reads = reads_of_view_[view];
    tbb::parallel_for(size_t{0}, reads.size(), [&](size_t i) {
      const Eigen::Vector2d uv = v.camera.Project(v.pose.Transform(samples_[reads[i] / 2].Point(mesh_)));
      colour_[reads[i]] = Bilinear(image, uv.x(), uv.y());
    });
    std::vector<size_t>().swap(reads);
  }
  std::vector<Eigen::Vector3f> Gains(size_t num_views, const AtlasOptions& options, AtlasStats* stats) const;

 private:
  struct Sample {
    uint32_t face;
    uint8_t edge, step;  // the face's edge k, and t = step / 2 along it
    Eigen::Vector3d Point(const ColoredMesh& m) const {
      const double t = 0.5 * step;
      return (1 - t) * m.vertices[m.triangles[face][edge]] + t * m.vertices[m.triangles[face][(edge + 1) % 3]];
    }
  };
  // Read 2s is sample s in its face's view, read 2s + 1 in the neighbour's.
  int ViewOf(size_t read) const {
    const Sample& sm = samples_[read / 2];
    return read % 2 == 0 ? labels_[sm.face] : labels_[adjacency_[sm.face][sm.edge]];
  }

  const ColoredMesh& mesh_;
  const std::vector<Eigen::Vector3i>& adjacency_;
  const std::vector<int>& labels_;
  std::vector<Sample> samples_;
  std::vector<std::vector<size_t>> reads_of_view_;
  std::vector<Eigen::Vector3f> colour_;  // per read
  size_t seam_edges_ = 0;
};

std::vector<Eigen::Vector3f> SeamSamples::Gains(size_t num_views, const AtlasOptions& options,
                                                AtlasStats* stats) const {
  auto& st = *stats;
  std::vector<Eigen::Vector3f> gain(num_views, Eigen::Vector3f::Ones());
  st.seam_edges = seam_edges_;
  if (!options.adjust_colors || num_views < 2) return gain;
  const int nvw = static_cast<int>(num_views);
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(nvw, nvw);
  Eigen::MatrixXd b = Eigen::MatrixXd::Zero(nvw, 3);
  for (size_t s = 0; s < samples_.size(); ++s) {
    const int va = ViewOf(2 * s), vb = ViewOf(2 * s + 1);
    const Eigen::Vector3f &ca = colour_[2 * s], &cb = colour_[2 * s + 1];
    // log(ca) + ga = log(cb) + gb
    A(va, va) += 1, A(vb, vb) += 1, A(va, vb) -= 1, A(vb, va) -= 1;
    for (int ch = 0; ch < 3; ++ch) {
      const double d = std::log(cb[ch] + 1.0) - std::log(ca[ch] + 1.0);
      b(va, ch) += d;
      b(vb, ch) -= d;
    }
  }
  // Regularisation relative to the mean number of seam terms per view keeps the gains near 1 where a view
  // has few seams, and fixes the common scale (no seam says anything about it).
  const double lambda = options.gain_regularisation * std::max(1.0, A.trace() / nvw);
  A.diagonal().array() += lambda;
  const Eigen::MatrixXd g = A.ldlt().solve(b);
  double max_dev = 0;
  for (int v = 0; v < nvw; ++v)
    for (int ch = 0; ch < 3; ++ch) {
      gain[v][ch] = static_cast<float>(std::clamp(std::exp(g(v, ch)), 0.5, 2.0));
      max_dev = std::max(max_dev, std::abs(gain[v][ch] - 1.0));
    }
  st.max_gain_deviation = max_dev;
  return gain;
}

// 3. Charts: per view, the faces it textures are drawn into a mask, grown by the margin; each connected
// region of the mask is one chart (its bounding box is copied), so nearby patches share their pixels and
// a view's scattered patches do not drag the whole frame into the atlas. Unseen faces get a flat chart each.
std::vector<Chart> MakeCharts(const ColoredMesh& mesh, const std::vector<TextureView>& views,
                              const std::vector<int>& labels, const std::vector<std::array<Eigen::Vector2d, 3>>& corner,
                              const AtlasOptions& options, std::vector<int>* chart_of_face_out, AtlasStats* stats) {
  const size_t nf = mesh.triangles.size();
  auto& st = *stats;
  std::vector<Chart> charts;
  std::vector<int>& chart_of_face = *chart_of_face_out;
  chart_of_face.assign(nf, -1);
  {
    std::vector<std::vector<int>> faces_of_view(views.size());
    for (size_t f = 0; f < nf; ++f)
      if (labels[f] >= 0) faces_of_view[labels[f]].push_back(static_cast<int>(f));
    const int pad = options.margin + 1;  // corners may lie up to half a pixel outside the image
    const cv::Mat kernel =
        cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * options.margin + 1, 2 * options.margin + 1));
    for (size_t v = 0; v < views.size(); ++v) {
      if (faces_of_view[v].empty()) continue;
      const core::Camera& cam = views[v].camera;
      cv::Mat mask = cv::Mat::zeros(cam.height + 2 * pad, cam.width + 2 * pad, CV_8U);
      const auto pixel = [&](const Eigen::Vector2d& p) {
        return cv::Point(std::clamp(static_cast<int>(std::floor(p.x())) + pad, 0, mask.cols - 1),
                         std::clamp(static_cast<int>(std::floor(p.y())) + pad, 0, mask.rows - 1));
      };
      for (int f : faces_of_view[v]) {
        cv::Point pts[3];
        for (int k = 0; k < 3; ++k)
          pts[k] = cv::Point(static_cast<int>(std::lround((corner[f][k].x() + pad) * 16)),
                             static_cast<int>(std::lround((corner[f][k].y() + pad) * 16)));
        cv::fillConvexPoly(mask, pts, 3, cv::Scalar(255), cv::LINE_8, 4);
        mask.at<uint8_t>(pixel(corner[f][0])) = 255;  // sub-pixel faces: at least their first corner
      }
      if (options.margin > 0) cv::dilate(mask, mask, kernel);
      cv::Mat component, box, centroids;
      const int n = cv::connectedComponentsWithStats(mask, component, box, centroids, 8, CV_32S);
      const int base = static_cast<int>(charts.size()) - 1;  // component 0 is the background
      for (int c = 1; c < n; ++c) {
        Chart ch;
        ch.view = static_cast<int>(v);
        ch.x0 = box.at<int>(c, cv::CC_STAT_LEFT) - pad;
        ch.y0 = box.at<int>(c, cv::CC_STAT_TOP) - pad;
        ch.x1 = ch.x0 + box.at<int>(c, cv::CC_STAT_WIDTH);
        ch.y1 = ch.y0 + box.at<int>(c, cv::CC_STAT_HEIGHT);
        charts.push_back(ch);
      }
      for (int f : faces_of_view[v]) chart_of_face[f] = base + component.at<int>(pixel(corner[f][0]));
    }
  }
  const size_t view_charts = charts.size();
  // Unseen faces: one 4×4 block each (a 2×2 interior for the face plus a 1-texel border of the same colour).
  for (size_t f = 0; f < nf; ++f) {
    if (labels[f] >= 0) continue;
    Chart c;
    c.w = c.h = 4;
    Eigen::Vector3f rgb = Eigen::Vector3f::Constant(128);
    if (!mesh.colors.empty()) {
      rgb.setZero();
      for (int k = 0; k < 3; ++k) rgb += mesh.colors[mesh.triangles[f][k]].cast<float>() / 3.0f;
    }
    c.flat_bgr = Eigen::Vector3f(rgb[2], rgb[1], rgb[0]);
    chart_of_face[f] = static_cast<int>(charts.size());
    charts.push_back(c);
  }
  for (size_t c = 0; c < view_charts; ++c) {
    Chart& ch = charts[c];
    const int sw = ch.x1 - ch.x0, sh = ch.y1 - ch.y0;
    // A chart larger than a page (images wider than the page) is shrunk to fit.
    ch.scale = std::min(options.texel_scale, static_cast<double>(options.max_page_size) / std::max(sw, sh));
    ch.w = std::clamp(static_cast<int>(std::ceil(sw * ch.scale)), 1, options.max_page_size);
    ch.h = std::clamp(static_cast<int>(std::ceil(sh * ch.scale)), 1, options.max_page_size);
  }
  st.charts = view_charts;
  st.unseen_faces = charts.size() - view_charts;

  return charts;
}

// 4. Shelf packing of the charts into pages, tallest first; the pages made, with the flat charts in them.
std::vector<cv::Mat> PackCharts(std::vector<Chart>* charts_io, const AtlasOptions& options, AtlasStats* stats) {
  std::vector<Chart>& charts = *charts_io;
  auto& st = *stats;
  double area = 0;
  int widest = 1;
  for (const Chart& c : charts) area += static_cast<double>(c.w) * c.h, widest = std::max(widest, c.w);
  const int page_w = std::min(
      options.max_page_size, std::max(NextPow2(widest), NextPow2(static_cast<int>(std::ceil(std::sqrt(area * 1.15))))));
  std::vector<int> order(charts.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return charts[a].h > charts[b].h; });
  std::vector<int> page_used_h;
  {
    int page = 0, x = 0, y = 0, shelf_h = 0;
    page_used_h.push_back(0);
    for (int i : order) {
      Chart& c = charts[i];
      if (x + c.w > page_w) x = 0, y += shelf_h, shelf_h = 0;
      if (y + c.h > options.max_page_size) {
        ++page, x = 0, y = 0, shelf_h = 0;
        page_used_h.push_back(0);
      }
      c.page = page, c.px = x, c.py = y;
      x += c.w;
      shelf_h = std::max(shelf_h, c.h);
      page_used_h[page] = std::max(page_used_h[page], y + c.h);
    }
  }
  const int num_pages = static_cast<int>(page_used_h.size());
  std::vector<cv::Mat> pages(num_pages);
  for (int p = 0; p < num_pages; ++p)
    pages[p] = cv::Mat(std::min(options.max_page_size, NextPow2(page_used_h[p])), page_w, CV_8UC3, cv::Scalar(0, 0, 0));
  for (const Chart& c : charts)
    if (c.view < 0)
      pages[c.page](cv::Rect(c.px, c.py, c.w, c.h)).setTo(cv::Scalar(c.flat_bgr[0], c.flat_bgr[1], c.flat_bgr[2]));
  st.pages = num_pages;
  for (const auto& p : pages) st.page_size.emplace_back(p.cols, p.rows);
  st.atlas_fill =
      area / (static_cast<double>(page_w) *
              std::accumulate(pages.begin(), pages.end(), 0.0, [](double s, const cv::Mat& m) { return s + m.rows; }));

  return pages;
}

// 5. The textured mesh: one uv per (vertex, chart), faces grouped by page.
io::TexturedMesh UvMesh(const ColoredMesh& mesh, const std::vector<Chart>& charts,
                        const std::vector<int>& chart_of_face,
                        const std::vector<std::array<Eigen::Vector2d, 3>>& corner, const std::vector<cv::Mat>& pages) {
  const size_t nf = mesh.triangles.size();
  io::TexturedMesh out;
  out.vertices = mesh.vertices;
  out.normals = mesh.normals;
  for (size_t p = 0; p < pages.size(); ++p) {
    io::Material m;
    m.name = "atlas_" + std::to_string(p);
    m.diffuse_bgr = Eigen::Vector3f::Ones();
    m.texture = pages[p];
    out.materials.push_back(std::move(m));
  }
  std::unordered_map<uint64_t, int> uv_index;
  auto uv_of = [&](int vertex, int chart, const Eigen::Vector2f& uv) {
    const uint64_t key = static_cast<uint64_t>(vertex) * charts.size() + chart;
    auto [it, fresh] = uv_index.emplace(key, static_cast<int>(out.uvs.size()));
    if (fresh) out.uvs.push_back(uv);
    return it->second;
  };
  std::vector<int> face_order(nf);
  std::iota(face_order.begin(), face_order.end(), 0);
  std::stable_sort(face_order.begin(), face_order.end(),
                   [&](int a, int b) { return charts[chart_of_face[a]].page < charts[chart_of_face[b]].page; });
  out.faces.reserve(nf);
  for (int f : face_order) {
    const int ci = chart_of_face[f];
    const Chart& c = charts[ci];
    const cv::Mat& page = pages[c.page];
    io::Face face;
    face.material = c.page;
    for (int k = 0; k < 3; ++k) {
      face.v[k] = mesh.triangles[f][k];
      if (!out.normals.empty()) face.vn[k] = face.v[k];
      Eigen::Vector2d t;  // texel coordinates in the page (corner convention)
      if (c.view >= 0) {
        // The chart was resized to w × h exactly (its scale rounded up to whole texels).
        const Eigen::Vector2d ratio(static_cast<double>(c.w) / (c.x1 - c.x0), static_cast<double>(c.h) / (c.y1 - c.y0));
        t = (corner[f][k] - Eigen::Vector2d(c.x0, c.y0)).cwiseProduct(ratio) + Eigen::Vector2d(c.px, c.py);
      } else {
        static const Eigen::Vector2d kFlat[3] = {{1.25, 1.25}, {2.75, 1.25}, {2.0, 2.75}};
        t = kFlat[k] + Eigen::Vector2d(c.px, c.py);
      }
      const Eigen::Vector2f uv(static_cast<float>(t.x() / page.cols), static_cast<float>(1.0 - t.y() / page.rows));
      face.vt[k] =
          c.view >= 0 ? uv_of(face.v[k], ci, uv) : static_cast<int>((out.uvs.push_back(uv), out.uvs.size() - 1));
    }
    out.faces.push_back(face);
  }
  out.Validate();

  return out;
}

// 6. Vertex colours from the texture (RGB), for the vertex-coloured PLY.
std::vector<io::Rgb8> VertexColours(const ColoredMesh& mesh, const io::TexturedMesh& out,
                                    const std::vector<cv::Mat>& pages) {
  const size_t nv = mesh.vertices.size();
  std::vector<Eigen::Vector3f> acc(nv, Eigen::Vector3f::Zero());
  std::vector<int> cnt(nv, 0);
  for (const io::Face& face : out.faces) {
    const cv::Mat& page = pages[face.material];
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector2f& uv = out.uvs[face.vt[k]];
      acc[face.v[k]] += Bilinear(page, uv.x() * page.cols, (1.0 - uv.y()) * page.rows);
      ++cnt[face.v[k]];
    }
  }
  std::vector<io::Rgb8> colors(nv);
  for (size_t v = 0; v < nv; ++v) {
    if (cnt[v] == 0) {
      colors[v] = mesh.colors.empty() ? io::Rgb8(128, 128, 128) : mesh.colors[v];
      continue;
    }
    const Eigen::Vector3f bgr = acc[v] / static_cast<float>(cnt[v]);
    for (int ch = 0; ch < 3; ++ch) colors[v][ch] = static_cast<uint8_t>(std::clamp(std::lround(bgr[2 - ch]), 0L, 255L));
  }
  return colors;
}

}  // namespace

TexturedModel BuildTextureAtlas(const ColoredMesh& mesh, const std::vector<Eigen::Vector3i>& adjacency,
                                const std::vector<TextureView>& views, FrameWindow& frames,
                                const std::vector<int>& labels, const AtlasOptions& options) {
  options.Check();
  const size_t nf = mesh.triangles.size();
  if (labels.size() != nf || adjacency.size() != nf) throw Error("texture: labels or adjacency do not match the mesh");
  TexturedModel model;
  AtlasStats& st = model.atlas;

  // Image coordinates of every labelled face corner (pixel-corner convention, camera.h).
  std::vector<std::array<Eigen::Vector2d, 3>> corner(nf);
  for (size_t f = 0; f < nf; ++f) {
    if (labels[f] < 0) continue;
    const TextureView& v = views[labels[f]];
    for (int k = 0; k < 3; ++k) corner[f][k] = v.camera.Project(v.pose.Transform(mesh.vertices[mesh.triangles[f][k]]));
  }

  // 1. Patches: edge-connected faces on the same view.
  UnionFind patches(nf);
  for (size_t f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k) {
      const int g = adjacency[f][k];
      if (g >= 0 && labels[f] >= 0 && labels[g] == labels[f]) patches.Union(static_cast<int>(f), g);
    }

  size_t num_patches = 0;
  for (size_t f = 0; f < nf; ++f)
    num_patches += labels[f] >= 0 && patches.Find(static_cast<int>(f)) == static_cast<int>(f);
  st.patches = num_patches;
  std::vector<int> chart_of_face;
  std::vector<Chart> charts = MakeCharts(mesh, views, labels, corner, options, &chart_of_face, &st);
  std::vector<cv::Mat> pages = PackCharts(&charts, options, &st);

  // One pass over the frame window reads the seam colours and copies the charts (they do not overlap on the
  // pages); the gains, which need every seam, are applied to the copies after it.
  SeamSamples seams(mesh, adjacency, labels, views.size(), options);
  std::vector<std::vector<size_t>> charts_of_view(views.size());
  for (size_t i = 0; i < charts.size(); ++i)
    if (charts[i].view >= 0) charts_of_view[charts[i].view].push_back(i);
  std::vector<size_t> read;
  for (size_t v = 0; v < views.size(); ++v)
    if (seams.Reads(v) || !charts_of_view[v].empty()) read.push_back(v);
  frames.ForEach(read, [&](size_t v, const cv::Mat& image) {
    seams.Read(v, views[v], image);
    for (size_t i : charts_of_view[v]) CopyChart(image, charts[i], &pages[charts[i].page]);
  });
  const std::vector<Eigen::Vector3f> gain = seams.Gains(views.size(), options, &st);
  for (const Chart& c : charts)
    if (c.view >= 0) ApplyGain(c, gain[c.view], &pages[c.page]);
  model.mesh = UvMesh(mesh, charts, chart_of_face, corner, pages);
  model.vertex_colors = VertexColours(mesh, model.mesh, pages);
  spdlog::info("texture: {} patches in {} charts on {} atlas page(s) of {} px wide ({:.0f}% filled)", num_patches,
               st.charts, pages.size(), pages.empty() ? 0 : pages.front().cols, 100 * st.atlas_fill);
  return model;
}

}  // namespace fmv3d::surface
