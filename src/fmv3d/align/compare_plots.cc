#include "fmv3d/align/compare_plots.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"

namespace fmv3d::align {
namespace {

const cv::Scalar kBlack(0, 0, 0), kGrid(225, 225, 225), kWhite(255, 255, 255);

void WritePng(const cv::Mat& img, const std::filesystem::path& png) {
  core::WriteAtomically(png, [&](const std::filesystem::path& tmp) {
    if (!cv::imwrite(tmp.string(), img)) throw Error(png.string() + ": cannot write PNG");
  });
}

// 1, 2 or 5 × 10^k at or above x.
double NiceCeil(double x) {
  if (!(x > 0)) return 1;
  const double p = std::pow(10.0, std::floor(std::log10(x)));
  for (double m : {1.0, 2.0, 5.0, 10.0})
    if (m * p >= x * (1 - 1e-12)) return m * p;
  return 10 * p;
}

std::string Num(double v) {
  if (v == 0) return "0";
  return fmt::format("{:.3g}", v);
}

void Text(cv::Mat& img, const std::string& s, cv::Point at, double size = 0.45, cv::Scalar colour = kBlack,
          bool centre = false) {
  int base = 0;
  const cv::Size ts = cv::getTextSize(s, cv::FONT_HERSHEY_SIMPLEX, size, 1, &base);
  if (centre) at.x -= ts.width / 2;
  cv::putText(img, s, at, cv::FONT_HERSHEY_SIMPLEX, size, colour, 1, cv::LINE_AA);
}

// Jet-like colour for t in [0, 1] (blue → cyan → yellow → red), BGR.
cv::Vec3b Colour(double t) {
  static const cv::Mat lut = [] {
    cv::Mat ramp(1, 256, CV_8UC1);
    for (int i = 0; i < 256; ++i) ramp.at<uint8_t>(0, i) = static_cast<uint8_t>(i);
    cv::Mat out;
    cv::applyColorMap(ramp, out, cv::COLORMAP_JET);
    return out;
  }();
  const int i = std::clamp(static_cast<int>(std::lround(t * 255)), 0, 255);
  return lut.at<cv::Vec3b>(0, i);
}

double AbsPercentile(const std::vector<double>& v, double q) {
  if (v.empty()) return 0;
  std::vector<double> a(v.size());
  for (size_t i = 0; i < v.size(); ++i) a[i] = std::abs(v[i]);
  const size_t k = std::min(a.size() - 1, static_cast<size_t>(q * (a.size() - 1)));
  std::nth_element(a.begin(), a.begin() + k, a.end());
  return a[k];
}

}  // namespace

void WriteHistogramPlot(const PlotInput& in, const std::filesystem::path& png) {
  const int W = 960, H = 540, left = 80, right = 30, top = 50, bottom = 70;
  cv::Mat img(H, W, CV_8UC3, kWhite);
  const std::vector<const std::vector<double>*> series = {&in.ex, &in.ey, &in.ez};
  const char* names[] = {"X", "Y", "Z"};
  const cv::Scalar colours[] = {cv::Scalar(40, 40, 220), cv::Scalar(40, 160, 40), cv::Scalar(220, 90, 30)};
  // Range: symmetric, covering the 99th percentile of every axis (in percent of H).
  double range = 0;
  for (const auto* s : series) range = std::max(range, 100 * AbsPercentile(*s, 0.99));
  range = NiceCeil(std::max(range, 1e-6));
  const int bins = 80;
  std::vector<std::vector<double>> share(3, std::vector<double>(bins, 0));
  double ymax = 0;
  for (int k = 0; k < 3; ++k) {
    const auto& s = *series[k];
    for (double v : s) {
      const double pct = 100 * v;
      if (std::abs(pct) > range) continue;
      const int b = std::min(bins - 1, static_cast<int>((pct + range) / (2 * range) * bins));
      share[k][b] += 1;
    }
    for (double& c : share[k]) {
      c = s.empty() ? 0 : 100 * c / s.size();
      ymax = std::max(ymax, c);
    }
  }
  ymax = NiceCeil(std::max(ymax, 1e-6));
  const int pw = W - left - right, ph = H - top - bottom;
  auto X = [&](double pct) { return left + static_cast<int>(std::lround((pct + range) / (2 * range) * pw)); };
  auto Y = [&](double sh) { return top + ph - static_cast<int>(std::lround(sh / ymax * ph)); };
  for (int i = 0; i <= 10; ++i) {
    const double xv = -range + i * range / 5, yv = i * ymax / 10;
    cv::line(img, {X(xv), top}, {X(xv), top + ph}, kGrid);
    cv::line(img, {left, Y(yv)}, {left + pw, Y(yv)}, kGrid);
    Text(img, Num(xv), {X(xv), top + ph + 18}, 0.42, kBlack, true);
    Text(img, Num(yv), {8, Y(yv) + 5}, 0.42);
  }
  cv::rectangle(img, {left, top}, {left + pw, top + ph}, kBlack);
  for (int k = 0; k < 3; ++k) {
    std::vector<cv::Point> poly;
    for (int b = 0; b < bins; ++b) {
      const double x0 = -range + 2 * range * b / bins, x1 = -range + 2 * range * (b + 1) / bins;
      poly.push_back({X(x0), Y(share[k][b])});
      poly.push_back({X(x1), Y(share[k][b])});
    }
    cv::polylines(img, poly, false, colours[k], 2, cv::LINE_AA);
    double sum2 = 0;
    for (double v : *series[k]) sum2 += v * v;
    const double rms = series[k]->empty() ? 0 : 100 * std::sqrt(sum2 / series[k]->size());
    cv::line(img, {left + pw - 190, top + 20 + 22 * k}, {left + pw - 160, top + 20 + 22 * k}, colours[k], 2);
    Text(img, fmt::format("{}  RMS {:.3f}%", names[k], rms), {left + pw - 150, top + 25 + 22 * k});
  }
  Text(img, "Error per axis (point - closest CAD point), % of H", {W / 2, 30}, 0.6, kBlack, true);
  Text(img, "error, % of H", {left + pw / 2, H - 22}, 0.5, kBlack, true);
  Text(img, "% of points", {8, top - 12}, 0.45);
  WritePng(img, png);
}

void WriteErrorView(const PlotInput& in, ViewDirection view, const std::filesystem::path& png) {
  // Orthographic projection: (a, b) on the page, c = depth towards the viewer (larger = nearer, drawn later).
  auto project = [&](const Eigen::Vector3d& p) -> Eigen::Vector3d {
    return view == ViewDirection::kTop ? Eigen::Vector3d(p.x(), p.y(), p.z()) : Eigen::Vector3d(p.x(), p.z(), -p.y());
  };
  Eigen::AlignedBox2d box;
  for (const auto& v : in.cad.vertices) box.extend(project(v).head<2>());
  for (const auto& p : in.points) box.extend(project(p).head<2>());
  const int max_w = 1000, max_h = 800, margin = 30, bar = 110;
  const Eigen::Vector2d size = box.sizes().cwiseMax(1e-9);
  const double px = std::min((max_w - 2 * margin) / size.x(), (max_h - 2 * margin) / size.y());
  const int W = static_cast<int>(size.x() * px) + 2 * margin + bar,
            H = static_cast<int>(size.y() * px) + 2 * margin + 40;
  cv::Mat img(H, W, CV_8UC3, kWhite);
  auto page = [&](const Eigen::Vector3d& q) {
    return cv::Point(static_cast<int>(std::lround(margin + (q.x() - box.min().x()) * px)),
                     static_cast<int>(std::lround(40 + margin + (box.max().y() - q.y()) * px)));
  };
  // CAD faces, far to near, grey by how much they face the viewer.
  std::vector<std::pair<double, size_t>> order;
  for (size_t f = 0; f < in.cad.faces.size(); ++f) {
    double depth = 0;
    for (int k = 0; k < 3; ++k) depth += project(in.cad.vertices[in.cad.faces[f].v[k]]).z();
    order.push_back({depth, f});
  }
  std::sort(order.begin(), order.end());
  const Eigen::Vector3d to_viewer = view == ViewDirection::kTop ? Eigen::Vector3d(0, 0, 1) : Eigen::Vector3d(0, -1, 0);
  for (const auto& [depth, f] : order) {
    cv::Point tri[3];
    for (int k = 0; k < 3; ++k) tri[k] = page(project(in.cad.vertices[in.cad.faces[f].v[k]]));
    const double facing = std::abs(in.cad.FaceNormal(f).dot(to_viewer));
    const int g = static_cast<int>(150 + 80 * facing);
    cv::fillConvexPoly(img, tri, 3, cv::Scalar(g, g, g), cv::LINE_AA);
  }
  // Points, far to near, coloured by |distance| up to the 99th percentile.
  const double vmax = NiceCeil(std::max(100 * AbsPercentile(in.distance, 0.99), 1e-6));
  std::vector<std::pair<double, size_t>> porder;
  for (size_t i = 0; i < in.points.size(); ++i) porder.push_back({project(in.points[i]).z(), i});
  std::sort(porder.begin(), porder.end());
  const int radius = in.points.size() > 200000 ? 1 : 2;
  for (const auto& [depth, i] : porder) {
    const cv::Vec3b c = Colour(100 * std::abs(in.distance[i]) / vmax);
    cv::circle(img, page(project(in.points[i])), radius, cv::Scalar(c[0], c[1], c[2]), cv::FILLED);
  }
  // Colour bar.
  const int bx = W - bar + 30, by0 = 40 + margin, by1 = H - margin;
  for (int y = by0; y <= by1; ++y) {
    const cv::Vec3b c = Colour(double(by1 - y) / std::max(1, by1 - by0));
    cv::line(img, {bx, y}, {bx + 18, y}, cv::Scalar(c[0], c[1], c[2]));
  }
  cv::rectangle(img, {bx, by0}, {bx + 18, by1}, kBlack);
  Text(img, Num(vmax) + "%", {bx + 22, by0 + 5}, 0.42);
  Text(img, Num(vmax / 2) + "%", {bx + 22, (by0 + by1) / 2 + 5}, 0.42);
  Text(img, "0", {bx + 22, by1 + 5}, 0.42);
  Text(img,
       view == ViewDirection::kTop ? "Top view (x right, y up): |distance to CAD|, % of H"
                                   : "Side view from -y (x right, z up): |distance to CAD|, % of H",
       {margin, 28}, 0.55);
  WritePng(img, png);
}

void WriteCompareHtml(const nlohmann::json& j, const std::filesystem::path& html) {
  std::ostringstream h;
  h << "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>fmv3d compare</title>\n"
       "<style>body{font-family:sans-serif;margin:2em;max-width:1100px}table{border-collapse:collapse;"
       "margin:1em 0}td,th{border:1px solid #ccc;padding:4px 10px;text-align:right}th{background:#f2f2f2}"
       "img{max-width:100%;border:1px solid #ddd;margin:0.5em 0}</style></head><body>\n";
  h << "<h1>Reconstruction vs CAD</h1>\n<p>Reconstruction: <code>" << j.value("reconstruction", "")
    << "</code><br>CAD: <code>" << j.value("cad", "") << "</code><br>Length H = " << j.at("length").get<double>()
    << " (all errors in % of H)<br>Points measured: " << j.at("points").at("measured").get<size_t>() << " of "
    << j.at("points").at("total").get<size_t>() << " (" << j.at("points").at("cropped").get<size_t>()
    << " outside the CAD's box)<br>Alignment: " << j.at("coarse_alignment").get<std::string>();
  if (!j.at("icp").is_null())
    h << " + ICP (" << j.at("icp").at("estimation").get<std::string>() << ", "
      << j.at("icp").at("iterations").get<int>() << " iterations)";
  h << "</p>\n<table><tr><th></th><th>mean</th><th>std</th><th>RMS</th><th>|e| 50%</th><th>|e| 90%</th>"
       "<th>|e| 99%</th></tr>\n";
  for (const char* k : {"x", "y", "z", "total"}) {
    const auto& e = j.at("error").at(k);
    h << "<tr><th>" << (std::string(k) == "total" ? "signed distance" : std::string(k) + " component") << "</th>";
    for (const char* f :
         {"mean_percent", "std_percent", "rms_percent", "p50_abs_percent", "p90_abs_percent", "p99_abs_percent"})
      h << "<td>" << fmt::format("{:.3f}%", e.at(f).get<double>()) << "</td>";
    h << "</tr>\n";
  }
  h << "</table>\n<p>Completeness: <b>" << fmt::format("{:.1f}%", j.at("completeness_percent").get<double>())
    << "</b> of " << j.at("completeness_samples").get<size_t>() << " CAD surface samples"
    << (j.at("completeness_seen_only").get<bool>() ? " seen by the cameras" : "")
    << " have a reconstructed point within "
    << fmt::format("{:.3g}%", j.at("completeness_threshold_percent").get<double>()) << " of H.</p>\n"
    << "<h2>Error histograms</h2><img src=\"histograms.png\">\n<h2>Top view</h2><img src=\"top.png\">\n"
    << "<h2>Side view</h2><img src=\"side.png\">\n</body></html>\n";
  core::WriteTextFile(html, h.str());
}

}  // namespace fmv3d::align
