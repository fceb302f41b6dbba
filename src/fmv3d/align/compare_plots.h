// Pictures of a CAD comparison, drawn with OpenCV (the seed's Figures 11–13): the X, Y, Z error histograms
// in one plot, and orthographic top / side views of the CAD (grey, shaded by facing) with the measured points
// on it coloured by their distance. Plus the HTML page that shows them with the figures.
#pragma once

#include <Eigen/Core>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <vector>

#include "fmv3d/io/mesh.h"

namespace fmv3d::align {

struct PlotInput {
  const io::TexturedMesh& cad;
  const std::vector<Eigen::Vector3d>& points;  // in the CAD frame
  const std::vector<double>& ex;               // per point: error components and signed distance, fractions of H
  const std::vector<double>& ey;
  const std::vector<double>& ez;
  const std::vector<double>& distance;
  double length = 1;
};

enum class ViewDirection {
  kTop,   // looking down −z: x to the right, y up the page
  kSide,  // looking along +y: x to the right, z up the page
};

void WriteHistogramPlot(const PlotInput& in, const std::filesystem::path& png);
void WriteErrorView(const PlotInput& in, ViewDirection view, const std::filesystem::path& png);
// compare.html beside the PNGs: the figures of compare.json as tables, and the three pictures.
void WriteCompareHtml(const nlohmann::json& compare, const std::filesystem::path& html);

}  // namespace fmv3d::align
