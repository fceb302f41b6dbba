// Still images: reading any of bmp/png/jpg/tif (gif is read by ingest::ReadInputImage through FFmpeg, since
// OpenCV 4.6 has no GIF reader),
// writing atomically, and the few EXIF fields the intrinsics prior needs (camera make/model, focal length).
#pragma once

#include <filesystem>
#include <string>

#include <opencv2/core.hpp>

namespace fmv3d::io {

struct ExifInfo {
  std::string make, model;      // trimmed; empty when absent
  double focal_mm = 0;          // FocalLength; 0 when absent
  double focal_35mm = 0;        // FocalLengthIn35mmFilm; 0 when absent
  double focal_plane_x_res = 0; // FocalPlaneXResolution in pixels per mm (unit converted); 0 when absent
  int pixel_width = 0;          // PixelXDimension (the width the focal-plane resolution refers to)
  bool empty() const { return make.empty() && model.empty() && focal_mm == 0 && focal_35mm == 0; }
};

// Image file extensions we accept (lower case, with dot): .bmp .png .jpg .jpeg .gif .tif .tiff
bool HasImageExtension(const std::filesystem::path& path);
// Common video container extensions (.mp4 .avi .mpg .mpeg .ts .mov .mkv ...).
bool HasVideoExtension(const std::filesystem::path& path);

// Reads an image as 8-bit BGR, ignoring the EXIF orientation (pixels stay as the sensor recorded them, so
// the sensor geometry of the prior matches). Throws fmv3d::Error naming the file when it cannot be read
// (and for GIF, which OpenCV cannot decode: see ingest::ReadInputImage).
cv::Mat ReadImage(const std::filesystem::path& path);
// Image size without decoding the pixels when the format allows it (falls back to ReadImage).
cv::Size ReadImageSize(const std::filesystem::path& path);
// Writes an image (format from the extension) to a temporary name and renames it. Throws on failure.
void WriteImage(const std::filesystem::path& path, const cv::Mat& image);

// EXIF from a JPEG (APP1) or TIFF header. Never throws; returns an empty ExifInfo when there is none or it
// is malformed (every offset is bounds-checked).
ExifInfo ReadExif(const std::filesystem::path& path);
// The same parser on an in-memory TIFF structure ("II*\0..." or "MM\0*..."), exposed for tests.
ExifInfo ParseTiffExif(const unsigned char* data, size_t size);

}  // namespace fmv3d::io
