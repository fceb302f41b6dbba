// Still images: reading any of bmp/png/jpg/tif (GIF is read by ingest::ReadInputImage through FFmpeg, since
// OpenCV 4.6 has no GIF reader) and writing atomically. Their EXIF/XMP metadata: exif.h.
#pragma once

#include <filesystem>
#include <opencv2/core.hpp>
#include <string>

namespace fmv3d::io {

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

}  // namespace fmv3d::io
