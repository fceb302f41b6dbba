// The CAD coloured by a comparison's errors: the building's surface subdivided, each vertex carrying the mean
// signed error of the points near it, on a reconstruction whose error is known everywhere.
#include "fmv3d/align/error_mesh.h"

#include <gtest/gtest.h>

#include <cmath>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/geometry/mesh_distance.h"
#include "fmv3d/synth/scene.h"
#include "test_util.h"

namespace fmv3d::align {
namespace {

constexpr double kLength = 30;

TEST(ErrorMesh, VerticesCarryTheErrorOfThePointsNearThemAndHolesAreUnknown) {
  const io::TexturedMesh cad = synth::MakeBuilding(synth::BuildingSpec{}, 0);
  const geometry::MeshDistance md(cad);
  std::vector<int> faces;
  const auto samples = md.SampleSurface(0.2, &faces, 3);
  // The south half (y < 0) reconstructed: below z = 12 0.4% of H off the surface, above it 0.6% the other way;
  // nothing on the north half.
  std::vector<Eigen::Vector3d> points;
  std::vector<double> errors;
  for (size_t i = 0; i < samples.size(); ++i) {
    const Eigen::Vector3d n = md.Normal(faces[i]);
    if (samples[i].y() >= -0.5 || n.z() < -0.9) continue;
    const double e = samples[i].z() < 12 ? 0.004 : -0.006;
    points.push_back(samples[i] + e * kLength * n);
    errors.push_back(e);
  }
  ErrorMeshOptions o;
  o.max_edge = 0.5;
  o.radius = 0.6;
  o.scale = 0.008;
  o.length = kLength;
  const ErrorMesh m = BuildErrorMesh(cad, points, errors, o);
  ASSERT_EQ(m.error.size(), m.vertices.size());
  ASSERT_EQ(m.colors.size(), m.vertices.size());
  for (const auto& t : m.triangles)
    for (int k = 0; k < 3; ++k) {
      ASSERT_LT(t[k], static_cast<int>(m.vertices.size()));
      EXPECT_LE((m.vertices[t[k]] - m.vertices[t[(k + 1) % 3]]).norm(), o.max_edge + 1e-9);
    }
  // The subdivided surface is the CAD's: same area.
  double area = 0;
  for (const auto& t : m.triangles)
    area += 0.5 * (m.vertices[t[1]] - m.vertices[t[0]]).cross(m.vertices[t[2]] - m.vertices[t[0]]).norm();
  EXPECT_NEAR(area, cad.SurfaceArea(), 1e-6 * area);
  int low = 0, high = 0, north_known = 0;
  for (size_t i = 0; i < m.vertices.size(); ++i) {
    const Eigen::Vector3d& v = m.vertices[i];
    if (v.y() > 1.5 && v.z() > 0.5) north_known += std::isfinite(m.error[i]) ? 1 : 0;
    if (v.y() > -1.5 || v.z() < 1) continue;
    if (v.z() < 11) {
      ++low;
      ASSERT_TRUE(std::isfinite(m.error[i])) << v.transpose();
      EXPECT_NEAR(m.error[i], 0.004, 1e-6);
      EXPECT_LE((m.colors[i].cast<int>() - DivergingColor(0.5).cast<int>()).cwiseAbs().maxCoeff(), 1);
    } else if (v.z() > 13 && v.z() < 23) {
      ++high;
      ASSERT_TRUE(std::isfinite(m.error[i])) << v.transpose();
      EXPECT_NEAR(m.error[i], -0.006, 1e-6);
      EXPECT_LE((m.colors[i].cast<int>() - DivergingColor(-0.75).cast<int>()).cwiseAbs().maxCoeff(), 1);
    }
  }
  EXPECT_GT(low, 100);
  EXPECT_GT(high, 100);
  EXPECT_EQ(north_known, 0);
  EXPECT_GT(m.covered_fraction, 0.25);
  EXPECT_LT(m.covered_fraction, 0.75);
  // Colours: red outside, blue inside, white at zero, grey unknown.
  EXPECT_GT(DivergingColor(1)[0], 150);
  EXPECT_LT(DivergingColor(1)[2], 60);
  EXPECT_GT(DivergingColor(-1)[2], 150);
  EXPECT_LT(DivergingColor(-1)[0], 80);
  EXPECT_EQ(DivergingColor(0), io::Rgb8(245, 245, 245));
  EXPECT_EQ(DivergingColor(NAN), io::Rgb8(128, 128, 128));

  // The PLY: header counts and binary sizes (19 bytes a vertex, 13 a triangle).
  test::TempDir dir("fmv3d-error-mesh");
  WriteErrorMeshPly(m, dir / "cad_error.ply");
  const std::string bytes = core::ReadTextFile(dir / "cad_error.ply");
  const size_t body = bytes.find("end_header\n") + 11;
  EXPECT_NE(bytes.find("element vertex " + std::to_string(m.vertices.size()) + "\n"), std::string::npos);
  EXPECT_NE(bytes.find("property float error\n"), std::string::npos);
  EXPECT_EQ(bytes.size() - body, 19 * m.vertices.size() + 13 * m.triangles.size());

  // The triangle cap holds, by longer edges.
  o.max_triangles = 500;
  const ErrorMesh coarse = BuildErrorMesh(cad, points, errors, o);
  EXPECT_LE(coarse.triangles.size(), 500u);
  EXPECT_GE(coarse.triangles.size(), cad.faces.size());
  o.radius = 0;
  EXPECT_THROW(BuildErrorMesh(cad, points, errors, o), Error);
  o.radius = 0.4;
  errors.pop_back();
  EXPECT_THROW(BuildErrorMesh(cad, points, errors, o), Error);
}

}  // namespace
}  // namespace fmv3d::align
