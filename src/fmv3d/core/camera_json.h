// Intrinsics as JSON ({"f", "aspect", "u0", "v0", "k1", "k2", "p1", "p2"}), the one reader and writer shared by
// camera files, the sensor database, frames.json and the reports. Missing optional fields default to aspect 1, the
// image centre and no distortion; "f" is required.
#pragma once

#include <nlohmann/json.hpp>

#include "fmv3d/core/camera.h"

namespace fmv3d::core {

// Reads the intrinsics into `camera`, whose width and height must already be set (they give the default
// principal point). Throws nlohmann::json::exception when "f" is missing or a field has the wrong type.
void IntrinsicsFromJson(const nlohmann::json& j, Camera* camera);

// The intrinsics as the object IntrinsicsFromJson reads (all eight fields).
nlohmann::json IntrinsicsToJson(const Camera& camera);
// The same with the image size ("width", "height").
nlohmann::json CameraToJson(const Camera& camera);

}  // namespace fmv3d::core
