// OGC 3D Tiles 1.0 tile formats: Point Cloud (.pnts) and Batched 3D Model (.b3dm, a binary glTF with an empty
// batch), byte-exact to the specification: a 28-byte header (magic, version 1, byteLength, feature table JSON
// and binary lengths, batch table JSON and binary lengths), the feature table JSON padded with spaces and the
// binary body padded with zeros so that every section ends on an 8-byte boundary.
//
// Our .pnts carry POSITION (float32 x3, relative to RTC_CENTER), RGB (uint8 x3) and NORMAL (float32 x3) when
// the cloud has them — the semantics every 3D Tiles client reads (CesiumJS, 3DTilesRendererJS, loaders.gl) — and,
// when known, batch table properties "views" (UNSIGNED_BYTE SCALAR: how many images saw the point, capped at 255)
// and "sigma" (FLOAT SCALAR: the point's stated uncertainty along its normal, model units; at an 8-byte offset).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace fmv3d::io {

struct PntsTile {
  Eigen::Vector3d rtc_center = Eigen::Vector3d::Zero();  // positions are relative to it
  std::vector<Eigen::Vector3f> positions;
  std::vector<Eigen::Matrix<uint8_t, 3, 1>> colors;  // empty or one per point
  std::vector<Eigen::Vector3f> normals;              // empty or one per point
  std::vector<uint8_t> views;                        // empty or one per point (batch table "views")
  std::vector<float> sigma;                          // empty or one per point (batch table "sigma")
};

// Throws fmv3d::Error when the attribute sizes disagree.
std::string EncodePnts(const PntsTile& tile);
// The inverse for what EncodePnts writes (and POSITION_QUANTIZED / NORMAL_OCT16P / RGBA from other writers are
// refused); throws fmv3d::Error naming the inconsistency (sizes, magic, offsets out of range).
PntsTile DecodePnts(const std::string& bytes);

// A .b3dm holding one binary glTF (BATCH_LENGTH 0). Throws fmv3d::Error when `glb` is not a GLB.
std::string EncodeB3dm(const std::string& glb);

// The bounds of a GLB's POSITION accessors (their min/max), turned from glTF's +y up back to our z-up frame
// ((x, y, z)_gltf → (x, −z, y)), as 3D Tiles 1.0 does for glTF content. Throws fmv3d::Error on a malformed GLB.
Eigen::AlignedBox3d GlbBoundsZUp(const std::string& glb);

// A 3D Tiles "box" bounding volume of an axis-aligned box: centre, then the three half-axis vectors.
nlohmann::json BoxVolume(const Eigen::AlignedBox3d& box);

}  // namespace fmv3d::io
