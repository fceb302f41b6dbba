// The map view's data of a georeferenced workspace (GET /api/workspaces/{ws}/geo and /profile): the ENU origin
// and UTM zone from geo/georef.json, the products' WGS84 bounds (from the DSM's grid), the flight track from the
// frames' telemetry, each registered frame's ground footprint (its image corners cast from the georeferenced
// camera onto the level plane at the DSM's median height), and height profiles sampled from geo/dsm.tif.
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>

#include "fmv3d/server/validation.h"

namespace fmv3d::server {

// Null when the workspace has no geo/georef.json. Throws fmv3d::Error on a malformed georef.json.
nlohmann::json GeoJson(const std::filesystem::path& ws);

// `n` points evenly spaced from `from` to `to` (straight in the DSM's UTM zone): {"points": [{"lat", "lon",
// "distance_m", "height_m" (bilinear; null where a neighbouring cell has no data or outside the grid)}]}.
// Throws fmv3d::Error when the workspace has no DSM.
nlohmann::json ProfileJson(const std::filesystem::path& ws, const LatLon& from, const LatLon& to, int n);

}  // namespace fmv3d::server
