#include "fmv3d/core/reconstruction.h"

#include "fmv3d/core/error.h"

namespace fmv3d::core {

const Image* Reconstruction::FindImageByName(const std::string& name) const {
  for (const auto& [id, image] : images)
    if (image.name == name) return &image;
  return nullptr;
}

void Reconstruction::Validate() const {
  for (const auto& [id, image] : images) {
    if (!cameras.count(image.camera_id))
      throw Error("image " + image.name + " refers to missing camera " + std::to_string(image.camera_id));
    if (image.points2d.size() != image.point3d_ids.size())
      throw Error("image " + image.name + ": point2D and point3D id lists differ in size");
    for (int64_t pid : image.point3d_ids)
      if (pid != kNoPoint3D && !points.count(static_cast<uint64_t>(pid)))
        throw Error("image " + image.name + " refers to missing 3D point " + std::to_string(pid));
  }
  for (const auto& [id, point] : points)
    for (const auto& el : point.track) {
      auto it = images.find(el.image_id);
      if (it == images.end())
        throw Error("3D point " + std::to_string(id) + " refers to missing image " + std::to_string(el.image_id));
      if (el.point2d_idx >= it->second.points2d.size())
        throw Error("3D point " + std::to_string(id) + " refers to a missing 2D point of " + it->second.name);
    }
}

double Reconstruction::MeanTrackLength() const {
  if (points.empty()) return 0;
  size_t n = 0;
  for (const auto& [id, p] : points) n += p.track.size();
  return static_cast<double>(n) / points.size();
}

double Reconstruction::MeanReprojectionError() const {
  if (points.empty()) return 0;
  double sum = 0;
  for (const auto& [id, p] : points) sum += p.error;
  return sum / points.size();
}

void Reconstruction::Transform(const Sim3& sim) {
  for (auto& [id, p] : points) p.xyz = sim.Apply(p.xyz);
  for (auto& [id, image] : images) image.pose = sim.Apply(image.pose);
}

}  // namespace fmv3d::core
