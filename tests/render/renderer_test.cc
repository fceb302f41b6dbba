// The rasteriser against analytic ground truth: marked points land at camera.Project(pose.Transform(X)),
// the depth map equals ray–surface distances, and rendering is deterministic.
#include "fmv3d/render/renderer.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <random>

#include "fmv3d/core/error.h"
#include "fmv3d/render/texture.h"

namespace fmv3d::render {
namespace {

// Adds an axis-aligned quad in the plane z = z0 (counter-clockwise from above) with material `mat`.
void AddQuad(io::TexturedMesh* m, double x0, double y0, double x1, double y1, double z0, int mat) {
  const int b = static_cast<int>(m->vertices.size());
  m->vertices.push_back({x0, y0, z0});
  m->vertices.push_back({x1, y0, z0});
  m->vertices.push_back({x1, y1, z0});
  m->vertices.push_back({x0, y1, z0});
  io::Face f;
  f.material = mat;
  f.v[0] = b, f.v[1] = b + 1, f.v[2] = b + 2;
  m->faces.push_back(f);
  f.v[0] = b, f.v[1] = b + 2, f.v[2] = b + 3;
  m->faces.push_back(f);
}

io::TexturedMesh BlackGround() {
  io::TexturedMesh m;
  io::Material black, white;
  black.name = "black";
  black.diffuse_bgr.setZero();
  white.name = "white";
  white.diffuse_bgr.setOnes();
  m.materials = {black, white};
  AddQuad(&m, -200, -200, 200, 200, 0, 0);
  return m;
}

core::Pose ObliqueView() { return core::Pose::LookAt({-6, -25, 18}, {1, 2, 0}); }

RenderOptions Plain() {
  RenderOptions o;
  o.shading = false;
  o.noise_sigma = 0;
  return o;
}

// Intersection of the viewing ray through pixel uv with the plane z = 0.
Eigen::Vector3d OnGround(const core::Camera& cam, const core::Pose& pose, const Eigen::Vector2d& uv) {
  const Eigen::Vector3d d = pose.q.conjugate() * cam.Unproject(uv);
  const Eigen::Vector3d c = pose.Centre();
  return c + d * (-c.z() / d.z());
}

void CheckMarkers(const core::Camera& cam) {
  const core::Pose pose = ObliqueView();
  io::TexturedMesh mesh = BlackGround();
  // Markers at chosen places across the image (corners included, where distortion is strongest).
  const std::vector<Eigen::Vector2d> targets = {{320, 240}, {60, 50}, {590, 60}, {70, 420}, {600, 430}, {200, 330}};
  std::vector<Eigen::Vector3d> centres;
  std::vector<double> halves;
  for (const auto& t : targets) {
    const Eigen::Vector3d X = OnGround(cam, pose, t);
    const double h = 0.012 * (X - pose.Centre()).norm();  // marker half-size: ~6 px
    AddQuad(&mesh, X.x() - h, X.y() - h, X.x() + h, X.y() + h, 0.002, 1);
    centres.push_back({X.x(), X.y(), 0.002});
    halves.push_back(h);
  }
  const Renderer renderer(mesh);
  RenderOptions o = Plain();
  o.supersample = 4;
  const RenderResult r = renderer.Render(cam, pose, o);
  double worst_proj = 0, worst_outline = 0;
  for (size_t k = 0; k < centres.size(); ++k) {
    const Eigen::Vector2d p = cam.Project(pose.Transform(centres[k]));
    double sw = 0, su = 0, sv = 0;
    for (int y = static_cast<int>(p.y()) - 25; y <= static_cast<int>(p.y()) + 25; ++y)
      for (int x = static_cast<int>(p.x()) - 25; x <= static_cast<int>(p.x()) + 25; ++x) {
        if (x < 0 || y < 0 || x >= cam.width || y >= cam.height) continue;
        const double w = r.image.at<cv::Vec3b>(y, x)[1];
        sw += w;
        su += w * (x + 0.5);
        sv += w * (y + 0.5);
      }
    ASSERT_GT(sw, 255 * 20) << "marker " << k << " not visible";
    const Eigen::Vector2d centroid(su / sw, sv / sw);
    EXPECT_LT((centroid - p).norm(), 0.5)
        << "marker " << k << " at " << p.transpose() << " drawn at " << centroid.transpose();
    // Tighter: the area centroid of the projected marker outline (the centre's projection differs from it
    // by a perspective bias of a few hundredths of a pixel).
    std::vector<Eigen::Vector2d> q;
    const double h = halves[k];
    for (const auto& c :
         {Eigen::Vector2d(-h, -h), Eigen::Vector2d(h, -h), Eigen::Vector2d(h, h), Eigen::Vector2d(-h, h)})
      q.push_back(cam.Project(pose.Transform(centres[k] + Eigen::Vector3d(c.x(), c.y(), 0))));
    double area = 0;
    Eigen::Vector2d pc = Eigen::Vector2d::Zero();
    for (int i = 0; i < 4; ++i) {
      const Eigen::Vector2d& a = q[i];
      const Eigen::Vector2d& b = q[(i + 1) % 4];
      const double cr = a.x() * b.y() - b.x() * a.y();
      area += cr;
      pc += (a + b) * cr;
    }
    pc /= 3 * area;
    worst_proj = std::max(worst_proj, (centroid - p).norm());
    worst_outline = std::max(worst_outline, (centroid - pc).norm());
    EXPECT_LT((centroid - pc).norm(), 0.03) << "marker " << k << " outline centroid " << pc.transpose();
    // The face map at the projected pixel is the marker, and its depth is the point's camera z.
    const int x = static_cast<int>(p.x()), y = static_cast<int>(p.y());
    EXPECT_GE(r.face.at<int32_t>(y, x), 2);
    const Eigen::Vector3d at_centre = OnGround(cam, pose, {x + 0.5, y + 0.5}) + Eigen::Vector3d(0, 0, 0.002);
    EXPECT_NEAR(r.depth.at<float>(y, x), pose.Transform(at_centre).z(), 1e-3 * pose.Transform(at_centre).z());
  }
  std::printf("marker centroid vs projected centre: max %.4f px; vs projected outline centroid: max %.4f px\n",
              worst_proj, worst_outline);
}

TEST(Renderer, MarkedPointsLandAtTheirProjection) { CheckMarkers(core::Camera::Pinhole(640, 480, 520)); }

TEST(Renderer, MarkedPointsLandAtTheirProjectionWithDistortion) {
  core::Camera cam = core::Camera::Pinhole(640, 480, 520);
  cam.k1 = -0.18;
  cam.k2 = 0.04;
  cam.p1 = 0.002;
  cam.p2 = -0.001;
  cam.u0 = 322.7;
  cam.v0 = 236.1;
  cam.aspect = 1.01;
  CheckMarkers(cam);
}

TEST(Renderer, DepthEqualsRayDistanceToPlaneAndBox) {
  io::TexturedMesh mesh = BlackGround();
  // A 4 x 3 x 5 m box standing on the ground (outward-wound faces).
  const Eigen::Vector3d lo(-1, -0.5, 0), hi(3, 2.5, 5);
  const int b = static_cast<int>(mesh.vertices.size());
  for (int k = 0; k < 8; ++k)
    mesh.vertices.push_back({k & 1 ? hi.x() : lo.x(), k & 2 ? hi.y() : lo.y(), k & 4 ? hi.z() : lo.z()});
  const int quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& q : quads) {
    io::Face f;
    f.material = 1;
    f.v[0] = b + q[0], f.v[1] = b + q[1], f.v[2] = b + q[2];
    mesh.faces.push_back(f);
    f.v[0] = b + q[0], f.v[1] = b + q[2], f.v[2] = b + q[3];
    mesh.faces.push_back(f);
  }
  const Renderer renderer(mesh);
  core::Camera cam = core::Camera::Pinhole(343, 259, 300);  // odd size on purpose
  cam.k1 = -0.1;
  const core::Pose pose = ObliqueView();
  const RenderResult r = renderer.Render(cam, pose, Plain());
  ASSERT_EQ(r.depth.rows, 259);
  ASSERT_EQ(r.depth.cols, 343);
  const Eigen::Vector3d c = pose.Centre();
  int box_pixels = 0, ground_pixels = 0;
  double worst = 0;
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      const Eigen::Vector3d dcam = cam.Unproject({x + 0.5, y + 0.5});  // (x, y, 1): z-depth = ray parameter
      const Eigen::Vector3d d = pose.q.conjugate() * dcam;
      // Slab test for the box, then the ground plane.
      double t0 = 0, t1 = 1e30;
      for (int a = 0; a < 3; ++a) {
        double ta = (lo[a] - c[a]) / d[a], tb = (hi[a] - c[a]) / d[a];
        if (ta > tb) std::swap(ta, tb);
        t0 = std::max(t0, ta);
        t1 = std::min(t1, tb);
      }
      const bool hits_box = t0 <= t1;
      const double t = hits_box ? t0 : -c.z() / d.z();
      const float depth = r.depth.at<float>(y, x);
      if (t <= 0) {
        EXPECT_EQ(depth, 0.0f);
        continue;
      }
      // Skip pixels whose centre is within a hair of a silhouette edge (the visibility raster decides).
      const double rel = std::abs(depth - t) / t;
      if (rel > 1e-5) {
        bool near_edge = false;
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const int xx = std::clamp(x + dx, 0, cam.width - 1), yy = std::clamp(y + dy, 0, cam.height - 1);
            near_edge |= (r.face.at<int32_t>(yy, xx) >= 2) != hits_box;
          }
        if (near_edge) continue;
      }
      worst = std::max(worst, rel);
      (hits_box ? box_pixels : ground_pixels)++;
    }
  EXPECT_GT(box_pixels, 2000);
  EXPECT_GT(ground_pixels, 20000);
  EXPECT_LT(worst, 1e-5) << "relative depth error";  // float32 storage
  std::printf("depth: %d box + %d ground pixels, max relative error %.2e\n", box_pixels, ground_pixels, worst);
}

// The ground quad with a random texture over its whole extent.
io::TexturedMesh RandomlyTexturedGround() {
  io::TexturedMesh mesh = BlackGround();
  cv::Mat tex(64, 64, CV_8UC3);
  cv::randu(tex, 0, 255);
  mesh.materials[0].texture = tex;
  mesh.uvs = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
  mesh.faces[0].vt[0] = 0, mesh.faces[0].vt[1] = 1, mesh.faces[0].vt[2] = 2;
  mesh.faces[1].vt[0] = 0, mesh.faces[1].vt[1] = 2, mesh.faces[1].vt[2] = 3;
  return mesh;
}

// A principal point moved by whole pixels moves the image by exactly as many pixels (the camera and pose unchanged):
// a sign, half-pixel or aspect slip in how the rasteriser and the shading rays place it would show here.
TEST(Renderer, OffCentrePrincipalPointTranslatesTheImage) {
  const io::TexturedMesh mesh = RandomlyTexturedGround();  // the renderer keeps a reference
  const Renderer renderer(mesh);
  const auto centred = core::Camera::Pinhole(320, 240, 280);
  core::Camera shifted = centred;
  const int du = 7, dv = -5;
  shifted.u0 += du;
  shifted.v0 += dv;
  const RenderOptions o = Plain();
  const auto a = renderer.Render(centred, ObliqueView(), o), b = renderer.Render(shifted, ObliqueView(), o);
  const cv::Rect in_b(du, 0, 320 - du, 240 + dv), in_a(0, -dv, 320 - du, 240 + dv);  // b(x, y) = a(x − du, y − dv)
  EXPECT_EQ(cv::norm(a.image(in_a), b.image(in_b), cv::NORM_INF), 0);
  EXPECT_EQ(cv::norm(a.depth(in_a), b.depth(in_b), cv::NORM_INF), 0);
  EXPECT_GT(cv::norm(a.image, b.image, cv::NORM_L1), 320 * 240);  // not the same picture
}

TEST(Renderer, DeterministicAndNoiseFollowsTheSeed) {
  const io::TexturedMesh mesh = RandomlyTexturedGround();  // the renderer keeps a reference
  const Renderer renderer(mesh);
  const auto cam = core::Camera::Pinhole(320, 240, 280);
  RenderOptions o;
  o.noise_sigma = 3;
  o.noise_seed = 5;
  const auto a = renderer.Render(cam, ObliqueView(), o), b = renderer.Render(cam, ObliqueView(), o);
  EXPECT_EQ(cv::norm(a.image, b.image, cv::NORM_INF), 0);
  o.noise_seed = 6;
  const auto c = renderer.Render(cam, ObliqueView(), o);
  EXPECT_GT(cv::norm(a.image, c.image, cv::NORM_L1), 320 * 240);
  EXPECT_EQ(cv::norm(a.depth, c.depth, cv::NORM_INF), 0);
  // Exposure scales brightness.
  o.noise_sigma = 0;
  o.exposure = 0.5;
  const double dim = cv::mean(renderer.Render(cam, ObliqueView(), o).image)[1];
  o.exposure = 1.0;
  const double bright = cv::mean(renderer.Render(cam, ObliqueView(), o).image)[1];
  EXPECT_NEAR(dim / bright, 0.5, 0.05);
}

TEST(Renderer, BadOptionsThrow) {
  RenderOptions o;
  o.supersample = 0;
  EXPECT_THROW(o.Check(), Error);
  o = RenderOptions();
  o.exposure = -1;
  EXPECT_THROW(o.Check(), Error);
}

TEST(MipTexture, SamplesTexelCentresExactlyAndAveragesAtCoarseLevels) {
  cv::Mat img(8, 16, CV_8UC3);
  cv::randu(img, 0, 255);
  const MipTexture tex(img);
  EXPECT_EQ(tex.num_levels(), 5);  // 16x8, 8x4, 4x2, 2x1, 1x1
  for (int r = 0; r < 8; ++r)
    for (int c = 0; c < 16; ++c) {
      const Eigen::Vector3f s = tex.Sample((c + 0.5f) / 16, 1 - (r + 0.5f) / 8, 0);
      const cv::Vec3b p = img.at<cv::Vec3b>(r, c);
      for (int k = 0; k < 3; ++k) EXPECT_NEAR(s[k], p[k], 1e-3);
    }
  const cv::Scalar mean = cv::mean(img);
  const Eigen::Vector3f top = tex.Sample(0.3f, 0.6f, 10);
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(top[k], mean[k], 3.0);
}

}  // namespace
}  // namespace fmv3d::render
