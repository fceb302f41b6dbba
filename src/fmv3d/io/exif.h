// EXIF and XMP of still images (JPEG APP1 segments, TIFF IFDs): camera make/model/focal for the intrinsics
// prior, the GPS IFD as recorded, the capture time, and the raw XMP packet (parsed by telemetry/).
//
// Our own bounded parser rather than libexiv2: we need a dozen tags, the input is untrusted (every offset,
// count and length is checked against the buffer, IFD chains are bounded), and a small parser can be fuzzed
// in isolation (tests/fuzz/exif_fuzz.cc) without pulling a large C++ library and its own CVE history into
// every reader of a photo folder. Values are reported as recorded; judging them (datum, plausibility, fix
// quality) is telemetry's job (telemetry/photo_telemetry.h).
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>

namespace fmv3d::io {

// The GPS IFD (EXIF 2.32 §4.6.6), converted to numbers but not judged.
struct ExifGps {
  std::optional<double> latitude, longitude;  // decimal degrees, signed by GPSLatitudeRef / GPSLongitudeRef
  std::optional<double> altitude;             // metres, negative when GPSAltitudeRef = 1 (below the reference)
  std::optional<double> dop;                  // GPSDOP
  std::optional<double> horizontal_error;     // GPSHPositioningError (EXIF 2.31), metres
  char status = 0;                            // GPSStatus: 'A' measurement in progress, 'V' void; 0 absent
  char measure_mode = 0;                      // GPSMeasureMode: '2' or '3'; 0 absent
  std::string map_datum;                      // GPSMapDatum, e.g. "WGS-84"
  std::optional<double> utc_seconds;          // GPSDateStamp + GPSTimeStamp as seconds since 1970 (UTC)
  bool present() const { return latitude.has_value() || longitude.has_value() || altitude.has_value(); }
};

struct ExifInfo {
  std::string make, model;        // trimmed; empty when absent
  double focal_mm = 0;            // FocalLength; 0 when absent
  double focal_35mm = 0;          // FocalLengthIn35mmFilm; 0 when absent
  double focal_plane_x_res = 0;   // FocalPlaneXResolution in pixels per mm (unit converted); 0 when absent
  int pixel_width = 0;            // PixelXDimension (the width the focal-plane resolution refers to)
  std::string datetime_original;  // DateTimeOriginal "YYYY:MM:DD HH:MM:SS" (local time of the camera)
  ExifGps gps;
  std::string xmp;       // the XMP packet (JPEG APP1 "http://ns.adobe.com/xap/1.0/", TIFF tag 700)
  bool damaged = false;  // an EXIF block is there but its TIFF header or first IFD cannot be read
  // True when none of the camera fields (make, model, focal) is present.
  bool empty() const { return make.empty() && model.empty() && focal_mm == 0 && focal_35mm == 0; }
};

// EXIF (and XMP) from a JPEG or a TIFF file. Never throws; returns an empty ExifInfo when there is none or it
// is malformed (every offset is bounds-checked; what can be read before the damage is kept).
ExifInfo ReadExif(const std::filesystem::path& path);
// The EXIF parser on an in-memory TIFF structure ("II*\0..." or "MM\0*...", the body of a JPEG's "Exif\0\0"
// APP1 segment or a whole TIFF file). Never throws, never reads outside [data, data + size).
ExifInfo ParseTiffExif(const unsigned char* data, size_t size);
// The metadata of an in-memory JPEG (its APP1 segments up to the first scan) or TIFF file, as ReadExif.
ExifInfo ParseImageMetadata(const unsigned char* data, size_t size);

}  // namespace fmv3d::io
