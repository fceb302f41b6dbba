#include "fmv3d/pipeline/report.h"

#include <spdlog/spdlog.h>

#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <sstream>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/workspace.h"
#include "fmv3d/features/feature_io.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/io/frames_index.h"
#include "fmv3d/io/obj_io.h"
#include "fmv3d/io/point_cloud.h"
#include "fmv3d/pipeline/coverage.h"
#include "fmv3d/pipeline/preview.h"
#include "fmv3d/surface/colored_mesh.h"

namespace fmv3d::pipeline {

namespace fs = std::filesystem;

namespace {

nlohmann::json ReadIfPresent(const fs::path& p) {
  if (!fs::exists(p)) return nullptr;
  try {
    return core::ReadJson(p);
  } catch (const std::exception& e) {
    spdlog::warn("report: {} unreadable ({}), left out", p.string(), e.what());
    return nullptr;
  }
}

void WritePng(const fs::path& path, const cv::Mat& image) {
  core::WriteAtomically(path, [&](const fs::path& tmp) {
    if (!cv::imwrite(tmp.string(), image)) throw Error(tmp.string() + ": cannot write PNG");
  });
}

std::string Escape(const std::string& s) {
  std::string o;
  for (char c : s) {
    if (c == '<')
      o += "&lt;";
    else if (c == '>')
      o += "&gt;";
    else if (c == '&')
      o += "&amp;";
    else
      o += c;
  }
  return o;
}

std::string Num(const nlohmann::json& j, int precision = 3) {
  if (j.is_number_float()) {
    std::ostringstream s;
    s.setf(std::ios::fixed);
    s.precision(precision);
    s << j.get<double>();
    return s.str();
  }
  if (j.is_null()) return "—";
  return j.is_string() ? j.get<std::string>() : j.dump();
}

// Pictures, all from one virtual viewpoint so they can be compared side by side. A picture that cannot be drawn
// leaves the report without it (and says why in "pictures_error").
nlohmann::json WritePictures(const core::Workspace& ws, nlohmann::json* report) {
  nlohmann::json images = nlohmann::json::array();
  try {
    if (fs::exists(ws.sparse_dir() / "images.txt")) {
      const core::Reconstruction rec = io::ReadColmapText(ws.sparse_dir());
      const io::OrientedPointCloud sparse = SparseCloud(rec);
      if (!sparse.empty()) {
        const View view = SceneView(rec, sparse.positions, 1024, 768);
        const double extent = (view.pose.Centre() - sparse.positions[0]).norm();  // ~ viewing distance
        cv::Mat img = RenderPoints(sparse, view, 2);
        DrawCameras(img, rec, view, 0.025 * extent);
        WritePng(ws.report_dir() / "sparse.png", img);
        images.push_back({{"file", "sparse.png"}, {"title", "Sparse model and cameras"}});
        const fs::path fused = ws.dense_dir() / "fused.ply";
        if (fs::exists(fused)) {
          const io::OrientedPointCloud dense = io::ReadPointCloudPly(fused);
          WritePng(ws.report_dir() / "dense.png", RenderPoints(dense, view, 1));
          images.push_back({{"file", "dense.png"}, {"title", "Dense oriented points"}});
        }
        // The textured mesh when there is one, else the Poisson surface (shaded).
        const fs::path obj = ws.mesh_dir() / "textured.obj", ply = ws.mesh_dir() / "poisson.ply";
        if (fs::exists(obj)) {
          WritePng(ws.report_dir() / "mesh.png", RenderMesh(io::ReadObj(obj), view));
          images.push_back({{"file", "mesh.png"}, {"title", "Textured mesh"}});
        } else if (fs::exists(ply)) {
          WritePng(ws.report_dir() / "mesh.png", RenderMesh(surface::ReadMeshPly(ply).ToTexturedMesh(), view));
          images.push_back({{"file", "mesh.png"}, {"title", "Poisson surface"}});
        }
      }
    }
  } catch (const std::exception& e) {
    spdlog::warn("report: pictures left out ({})", e.what());
    (*report)["pictures_error"] = e.what();
  }
  return images;
}

// Coverage: what share of every view the mesh and the dense cloud hold (pipeline/coverage.h).
void AddCoverage(const core::Workspace& ws, nlohmann::json* report) {
  try {
    if (fs::exists(ws.sparse_dir() / "images.txt") &&
        (fs::exists(ws.dense_dir() / "fused.ply") || fs::exists(ws.mesh_dir() / "poisson.ply"))) {
      const CoverageReport coverage = ComputeWorkspaceCoverage(ws.root(), CoverageOptions{});
      (*report)["coverage"] = coverage.ToJson();
      core::WriteJson(ws.report_dir() / "coverage.json", (*report)["coverage"]);
    }
  } catch (const std::exception& e) {
    spdlog::warn("report: coverage left out ({})", e.what());
    (*report)["coverage_error"] = e.what();
  }
}

// HTML: a table of the headline figures, timings, pictures, and the full JSON for the curious.
std::string ReportHtml(nlohmann::json report) {  // by value: operator[] inserts the keys it reads
  std::ostringstream h;
  h << "<!doctype html><html><head><meta charset=\"utf-8\"><title>fmv3d report</title><style>"
       "body{font-family:sans-serif;margin:2em;background:#fafafa}table{border-collapse:collapse}"
       "td,th{border:1px solid #ccc;padding:4px 10px;text-align:left}img{max-width:100%;border:1px solid #999}"
       "figure{display:inline-block;margin:0 1em 1em 0;width:48%}pre{background:#eee;padding:1em;overflow:auto}"
       "</style></head><body><h1>fmv3d reconstruction report</h1>\n";
  h << "<p>Workspace: <code>" << Escape(report["workspace"].get<std::string>()) << "</code></p>\n";
  h << "<h2>Summary</h2><table>\n";
  auto row = [&](const std::string& k, const std::string& v) {
    h << "<tr><th>" << Escape(k) << "</th><td>" << Escape(v) << "</td></tr>\n";
  };
  if (report["project"].is_object() && report["project"].contains("inputs"))
    for (const auto& in : report["project"]["inputs"]) row("input", in.get<std::string>());
  if (report.contains("frames")) row("frames", Num(report["frames"]["count"]));
  if (report["frames"].is_object())
    for (const auto& c : report["frames"]["cameras"])
      row("camera " + Num(c["id"]), Num(c["width"]) + "x" + Num(c["height"]) + ", focal prior " +
                                        Num(c["focal_prior_px"], 1) + " px (" + Num(c["prior"]) + ")");
  if (report["features"].is_object())
    row("keypoints (total)", Num(report["features"].value("total_keypoints", nlohmann::json())));
  if (report["sparse"].is_object()) {
    const auto& s = report["sparse"];
    row("registered frames",
        Num(s.value("registered_images", nlohmann::json())) + " / " + Num(s.value("total_images", nlohmann::json())));
    row("sparse points", Num(s.value("points", nlohmann::json())));
    row("mean track length", Num(s.value("mean_track_length", nlohmann::json()), 2));
    row("mean reprojection error (px)", Num(s.value("mean_reprojection_error_px", nlohmann::json()), 3));
  }
  if (report["dense"].is_object()) row("dense points", Num(report["dense"].value("points", nlohmann::json())));
  if (report["mesh"].is_object()) {
    row("mesh vertices", Num(report["mesh"].value("vertices", nlohmann::json())));
    row("mesh faces", Num(report["mesh"].value("faces", nlohmann::json())));
  }
  if (report["coverage"].is_object()) {
    const auto& c = report["coverage"];
    auto pct = [](const nlohmann::json& v) { return v.is_number() ? Num(100 * v.get<double>(), 1) + "%" : "—"; };
    row("coverage of the views' non-sky pixels, median (mesh / dense)",
        pct(c["median_mesh"]) + " / " + pct(c["median_dense"]));
  }
  h << "</table>\n<h2>Time per stage (s)</h2><table>\n";
  for (auto it = report["timings_seconds"].begin(); it != report["timings_seconds"].end(); ++it)
    row(it.key(), Num(it.value(), 1));
  h << "</table>\n<h2>Pictures</h2>\n";
  for (const auto& im : report["pictures"])
    h << "<figure><img src=\"" << im["file"].get<std::string>() << "\"><figcaption>"
      << Escape(im["title"].get<std::string>()) << "</figcaption></figure>\n";
  if (report["coverage"].is_object() && !report["coverage"]["pictures"].empty()) {
    h << "<h2>Least covered views</h2><p>Frame | mesh seen from the frame's camera | frame with the non-sky pixels "
         "the model leaves out in red (sky in blue)</p>\n";
    auto pct = [](const nlohmann::json& x) { return x.is_number() ? Num(100 * x.get<double>(), 1) + "%" : "—"; };
    for (const auto& p : report["coverage"]["pictures"])
      h << "<figure style=\"width:100%\"><img src=\"" << p["file"].get<std::string>() << "\"><figcaption>"
        << Escape(p["image"].get<std::string>() + ": mesh " + pct(p["mesh"]) + ", dense " + pct(p["dense"]))
        << "</figcaption></figure>\n";
  }
  if (report["compare"].is_object())
    h << "<h2>Accuracy against the CAD model</h2><p><a href=\"compare/compare.html\">comparison report</a></p>\n";
  h << "<h2>All figures (report.json)</h2><pre>" << Escape(report.dump(2)) << "</pre></body></html>\n";
  return h.str();
}

}  // namespace

void RecordTimings(const fs::path& root, const nlohmann::json& timings) {
  const core::Workspace ws(root);
  core::EnsureDirectory(ws.report_dir());
  nlohmann::json all = ReadIfPresent(ws.report_dir() / "timings.json");
  if (!all.is_object()) all = nlohmann::json::object();
  for (auto it = timings.begin(); it != timings.end(); ++it)
    if (!it.value().is_string() || !all.contains(it.key())) all[it.key()] = it.value();
  core::WriteJson(ws.report_dir() / "timings.json", all);
}

nlohmann::json WriteReport(const fs::path& root) {
  const core::Workspace ws(root);
  core::EnsureDirectory(ws.report_dir());
  nlohmann::json all_timings = ReadIfPresent(ws.report_dir() / "timings.json");
  if (!all_timings.is_object()) all_timings = nlohmann::json::object();

  nlohmann::json report;
  report["workspace"] = fs::absolute(root).string();
  report["project"] = ReadIfPresent(ws.project_json());
  report["timings_seconds"] = all_timings;
  if (fs::exists(ws.frames_json())) {
    const io::FramesIndex index = io::ReadFramesIndex(ws.frames_json());
    nlohmann::json cams = nlohmann::json::array();
    for (const auto& c : index.cameras)
      cams.push_back({{"id", c.camera.id},
                      {"width", c.camera.width},
                      {"height", c.camera.height},
                      {"focal_prior_px", c.camera.f},
                      {"prior", io::PriorSourceName(c.prior_source)}});
    report["frames"] = {{"count", index.frames.size()}, {"cameras", cams}};
  }
  report["features"] = ReadIfPresent(ws.features_dir() / "features.json");
  report["matches"] = ReadIfPresent(features::MatchesSummaryPath(ws.matches_dir()));
  report["sparse"] = ReadIfPresent(ws.report_dir() / "sparse.json");
  report["dense"] = ReadIfPresent(ws.report_dir() / "dense.json");
  report["mesh"] = ReadIfPresent(ws.report_dir() / "mesh.json");
  report["texture"] = ReadIfPresent(ws.report_dir() / "texture.json");
  report["compare"] = ReadIfPresent(ws.report_dir() / "compare" / "compare.json");

  report["pictures"] = WritePictures(ws, &report);
  AddCoverage(ws, &report);
  core::WriteJson(ws.report_dir() / "report.json", report);
  core::WriteTextFile(ws.report_dir() / "report.html", ReportHtml(report));
  return report;
}

}  // namespace fmv3d::pipeline
