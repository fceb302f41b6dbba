// Accuracy of a georeferenced workspace against a `fmv3d synth --klv | --exif-gps | --gpmf` ground truth (truth.json's
// geo_origin, truth/ cameras, scene.obj), all compared in the workspace's georef ENU frame (through WGS84, so the two
// origins may differ; a workspace whose heights are MSL, as EXIF states them, is compared with the truth lowered by
// the geoid undulation at its origin):
//   cameras   absolute camera-centre error (RMS 3D, horizontal, vertical, bias) of geo/sparse_enu/
//   telemetry the telemetry's own error at the cameras (RMS per axis, and its mean: the floor of a
//             position-only georeference's translation error)
//   surface   absolute position error of the georeferenced reconstruction over the true mesh (the issue's
//             figure): true surface samples X (inside truth.json's bounds, in the field of view of ≥ 2
//             registered cameras) against S⁻¹(X), S the similarity of
//             geo/sparse_enu/'s camera centres onto the true ones — RMS 3D, horizontal, vertical, max
//   telemetry_track  the same floor over every packet of frames/telemetry.json (the floor of a fit on them)
//   points    distance of geo/sparse_enu/'s points to the true mesh (RMS, median)
//   dsm       geo/dsm.tif against the true mesh rasterised on the same grid, on cells that are seen and whose
//             true surface is flat around them (a height step inside a cell has no single true height):
//             RMS, bias (mean), RMS after removing the bias, and RMS as % of the building height; over the
//             modelled area (truth.json's bounds, as for "surface"), and as "whole_seen" over every compared cell
//             (synth's far-ground backdrop included)
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>

#include "fmv3d/core/workspace.h"

namespace fmv3d::geo {

nlohmann::json EvaluateGeoAgainstSynth(const core::Workspace& workspace, const std::filesystem::path& synth_dir);

}  // namespace fmv3d::geo
