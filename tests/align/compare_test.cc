// CAD comparison on a reconstruction whose errors are known: points sampled on the building's surface, moved
// along the normal by Gaussian noise of known sigma, with ground around it, expressed in a foreign frame.
#include "fmv3d/align/compare.h"

#include <gtest/gtest.h>

#include <random>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/geometry/mesh_distance.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/io/obj_io.h"
#include "fmv3d/surface/colored_mesh.h"
#include "fmv3d/synth/scene.h"
#include "test_util.h"

namespace fmv3d::align {
namespace {

constexpr double kH = 30;  // the building's ridge height

struct Fixture {
  io::TexturedMesh cad = synth::MakeBuilding(synth::BuildingSpec{}, 0);
  core::Sim3 to_recon;  // CAD frame → the reconstruction's own frame
  Fixture() {
    to_recon.s = 0.37;
    to_recon.q = Eigen::AngleAxisd(2.0, Eigen::Vector3d(0.3, -0.5, 0.8).normalized());
    to_recon.t = Eigen::Vector3d(4, -7, 2);
  }
  // Building surface points (optionally only where keep(p)), noise sigma along the normal (CAD units), plus
  // ground at z = 0 around the building. Returned in the reconstruction's frame.
  io::OrientedPointCloud Recon(double sigma, const std::function<bool(const Eigen::Vector3d&)>& keep = nullptr) const {
    const geometry::MeshDistance md(cad);
    std::vector<int> faces;
    const auto pts = md.SampleSurface(0.15, &faces, 9);
    std::mt19937_64 rng(4);
    std::normal_distribution<double> g(0, sigma);
    io::OrientedPointCloud c;
    for (size_t i = 0; i < pts.size(); ++i) {
      const Eigen::Vector3d n = md.Normal(faces[i]);
      if (n.z() < -0.9) continue;  // the underside is never seen
      if (keep && !keep(pts[i])) continue;
      c.positions.push_back(to_recon.Apply(pts[i] + g(rng) * n));
    }
    for (double x = -30; x <= 30; x += 0.5)
      for (double y = -25; y <= 25; y += 0.5)
        if (std::abs(x) > 10.5 || std::abs(y) > 6.5) c.positions.push_back(to_recon.Apply({x, y, 0.02 * g(rng)}));
    return c;
  }
};

TEST(CompareToCad, MeasuresKnownNoiseFromARoughTransform) {
  Fixture f;
  const double sigma = 0.004 * kH;  // 0.4% of H along the normal
  const io::OrientedPointCloud recon = f.Recon(sigma);
  CompareOptions o;
  o.length = kH;
  // The given transform is 1° and 1% off: ICP must take it the rest of the way.
  core::Sim3 rough = f.to_recon.Inverse();
  core::Sim3 err;
  err.s = 1.01;
  err.q = Eigen::AngleAxisd(M_PI / 180, Eigen::Vector3d::UnitZ());
  err.t = Eigen::Vector3d(0.2, 0.1, -0.1);
  o.transform = ComposeSim3(err, rough);
  const CompareResult r = CompareToCad(recon, f.cad, o);
  ASSERT_TRUE(r.icp.has_value());
  const core::Sim3 e = ComposeSim3(r.transform, f.to_recon);  // identity when perfect
  EXPECT_NEAR(e.s, 1, 5e-4);                                  // noise of 0.4% of H near edges biases a few 1e-4
  EXPECT_LT(core::RotationAngle(e.q, Eigen::Quaterniond::Identity()) * 180 / M_PI, 0.02);
  EXPECT_NEAR(r.total.rms, 0.004, 0.0004);
  EXPECT_NEAR(r.total.mean, 0, 0.0003);
  EXPECT_NEAR(r.total.p50, 0.6745 * 0.004, 0.0004);  // median |N(0, σ)|
  // The noise is along the normals: walls carry it in x or y, the roof in y and z; together it is the total.
  EXPECT_NEAR(std::pow(r.x.rms, 2) + std::pow(r.y.rms, 2) + std::pow(r.z.rms, 2), std::pow(r.total.rms, 2), 1e-7);
  EXPECT_GT(r.x.rms, 0.001);
  EXPECT_GT(r.z.rms, 0.001);
  EXPECT_GT(r.completeness, 0.97);
  EXPECT_GT(r.points_cropped, 10000u) << "the ground is not measured";

  // Without ICP, the 1% scale error shows up in the figures.
  o.icp = false;
  const CompareResult raw = CompareToCad(recon, f.cad, o);
  EXPECT_FALSE(raw.icp.has_value());
  EXPECT_GT(raw.total.rms, 1.5 * r.total.rms);
}

TEST(CompareToCad, CompletenessOverTheSurfaceTheCamerasSee) {
  Fixture f;
  // Only the south side (y < 0 walls and roof slope) is reconstructed; cameras look from the south.
  const io::OrientedPointCloud recon = f.Recon(0.001 * kH, [](const Eigen::Vector3d& p) { return p.y() < -0.5; });
  test::TempDir dir("fmv3d-compare");
  core::Reconstruction cams;
  cams.cameras[1] = core::Camera::Pinhole(320, 240, 260);
  for (int i = 0; i < 3; ++i) {
    core::Image im;
    im.id = i + 1;
    im.camera_id = 1;
    im.name = "view" + std::to_string(i) + ".png";
    im.pose = core::Pose::LookAt(Eigen::Vector3d(-20 + 20 * i, -70, 40), Eigen::Vector3d(0, 0, 14));
    cams.images[im.id] = im;
  }
  // The camera model lives in the CAD frame, as synth's truth/ does.
  io::WriteColmapText(cams, dir / "cams");
  CompareOptions o;
  o.length = kH;
  o.transform = f.to_recon.Inverse();
  const CompareResult all = CompareToCad(recon, f.cad, o);
  o.cameras = dir / "cams";
  o.output_dir = dir / "out";
  const CompareResult seen = CompareToCad(recon, f.cad, o);
  EXPECT_FALSE(all.completeness_seen_only);
  EXPECT_TRUE(seen.completeness_seen_only);
  EXPECT_LT(all.completeness, 0.75);
  EXPECT_GT(seen.completeness, 0.95);
  EXPECT_LT(seen.surface_samples, all.surface_samples);
  for (const char* name : {"compare.json", "compare.html", "histograms.png", "top.png", "side.png", "cad_error.ply"})
    EXPECT_TRUE(std::filesystem::exists(dir / "out" / name)) << name;
  const auto j = core::ReadJson(dir / "out/compare.json");
  EXPECT_NEAR(j.at("completeness_percent").get<double>(), 100 * seen.completeness, 1e-9);
  EXPECT_NEAR(j.at("error").at("total").at("rms_percent").get<double>(), 100 * seen.total.rms, 1e-9);
  // The CAD coloured by the error: the reconstructed south half known, the north half not.
  const auto& em = j.at("error_mesh");
  EXPECT_EQ(em.at("file"), "cad_error.ply");
  EXPECT_GT(em.at("triangles").get<int>(), 1000);
  EXPECT_GT(em.at("covered_percent").get<double>(), 25);
  EXPECT_LT(em.at("covered_percent").get<double>(), 75);
  EXPECT_NEAR(em.at("scale_percent").get<double>(), 100 * seen.total.p90, 1e-9);
}

TEST(CompareToCad, AMeshIsCompleteWhereItsFacesAreNotOnlyAtItsVertices) {
  // The CAD itself as a coarse reconstruction (10 vertices, large faces): exact, and complete as a surface,
  // though its vertices alone are far from almost every CAD sample.
  Fixture f;
  surface::ColoredMesh mesh;
  for (const auto& v : f.cad.vertices) mesh.vertices.push_back(f.to_recon.Apply(v));
  for (const auto& face : f.cad.faces) mesh.triangles.emplace_back(face.v[0], face.v[1], face.v[2]);
  mesh.ComputeVertexNormals();
  test::TempDir dir("fmv3d-compare-mesh");
  surface::WriteMeshPly(mesh, dir / "mesh.ply");
  io::WriteObj(f.cad, dir / "cad.obj");
  CompareOptions o;
  o.length = kH;
  o.transform = f.to_recon.Inverse();
  o.icp = false;  // too few vertices for ICP; the transform is exact
  o.reconstruction = dir / "mesh.ply";
  o.cad = dir / "cad.obj";
  const CompareResult as_mesh = CompareToCad(o);
  EXPECT_TRUE(as_mesh.completeness_from_faces);
  EXPECT_GT(as_mesh.completeness, 0.99);
  EXPECT_LT(as_mesh.total.rms, 1e-6);
  // The same vertices as a point cloud: only the samples near the corners are covered.
  io::OrientedPointCloud points;
  points.positions = mesh.vertices;
  const CompareResult as_points = CompareToCad(points, f.cad, o);
  EXPECT_FALSE(as_points.completeness_from_faces);
  EXPECT_LT(as_points.completeness, 0.05);
  EXPECT_EQ(as_points.points_measured, as_mesh.points_measured);
}

TEST(CompareToCad, Sim3JsonRoundTripAndErrors) {
  Fixture f;
  const core::Sim3 back = Sim3FromJson(Sim3ToJson(f.to_recon));
  EXPECT_NEAR(back.s, f.to_recon.s, 1e-15);
  EXPECT_LT(core::RotationAngle(back.q, f.to_recon.q), 1e-12);
  EXPECT_LT((back.t - f.to_recon.t).norm(), 1e-12);
  EXPECT_THROW(Sim3FromJson(nlohmann::json{{"scale", 1}}), Error);
  // The shape of evaluate-sparse's report.
  const Eigen::Quaterniond& q = f.to_recon.q;
  const nlohmann::json report = {{"alignment",
                                  {{"scale", f.to_recon.s},
                                   {"q_wxyz", {q.w(), q.x(), q.y(), q.z()}},
                                   {"t", {f.to_recon.t.x(), f.to_recon.t.y(), f.to_recon.t.z()}}}}};
  const core::Sim3 from_report = Sim3FromJson(report);
  EXPECT_LT(core::RotationAngle(from_report.q, f.to_recon.q), 1e-12);
  EXPECT_LT((from_report.t - f.to_recon.t).norm(), 1e-12);
  nlohmann::json bad = Sim3ToJson(f.to_recon);
  bad["rotation"][0][0] = 2.0;
  EXPECT_THROW(Sim3FromJson(bad), Error);
  bad = Sim3ToJson(f.to_recon);
  bad["scale"] = -1;
  EXPECT_THROW(Sim3FromJson(bad), Error);
  CompareOptions o;
  EXPECT_THROW(CompareToCad(f.Recon(0.01), f.cad, o), Error) << "length 0";
  o.length = kH;
  core::Sim3 far;
  far.t = Eigen::Vector3d(1e5, 0, 0);
  o.transform = far;
  EXPECT_THROW(CompareToCad(f.Recon(0.01), f.cad, o), Error) << "nothing near the CAD";
}

TEST(CompareCli, WritesReportAndRejectsBadInput) {
  Fixture f;
  test::TempDir dir("fmv3d-compare-cli");
  io::WriteObj(f.cad, dir / "cad.obj");
  io::WritePointCloudPly(f.Recon(0.002 * kH), dir / "recon.ply");
  core::WriteJson(dir / "sim.json", Sim3ToJson(f.to_recon.Inverse()));
  const std::string base = "compare " + (dir / "recon.ply").string() + " --cad " + (dir / "cad.obj").string();
  auto r =
      test::RunCli(base + " --length 30 --transform " + (dir / "sim.json").string() + " -o " + (dir / "out").string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("completeness"), std::string::npos) << r.out;
  EXPECT_TRUE(std::filesystem::exists(dir / "out/compare.html"));
  core::WriteTextFile(dir / "bad.json", "{\"scale\": 1, \"rotation\": [[1,0,0],[0,1,0]], \"translation\": [0,0,0]}");
  r = test::RunCli(base + " --length 30 --transform " + (dir / "bad.json").string() + " -o " + (dir / "o2").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("bad.json"), std::string::npos) << r.err;
  r = test::RunCli(base + " --length 0 -o " + (dir / "o3").string());
  EXPECT_EQ(r.exit_code, 2) << "usage error";
}

}  // namespace
}  // namespace fmv3d::align
