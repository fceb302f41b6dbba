// libFuzzer target for the photo metadata readers: JPEG/TIFF EXIF (io/exif.h), the DJI XMP scan and the photo
// telemetry built from them (telemetry/photo_telemetry.h). Whatever the bytes, nothing may crash or trip
// ASan/UBSan, and a sample that comes out must have passed the fix screening (a finite position on the globe).
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>

#include "fmv3d/io/exif.h"
#include "fmv3d/telemetry/photo_telemetry.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace fmv3d;
  io::ExifInfo e = io::ParseImageMetadata(data, size);
  if (e.xmp.empty()) e.xmp.assign(reinterpret_cast<const char*>(data), size);  // the bytes as XMP text too
  const telemetry::PhotoTelemetry t = telemetry::TelemetryFromPhoto(e, {});
  if (t.sample) {
    const double lat = *t.sample->sensor_latitude, lon = *t.sample->sensor_longitude;
    if (!std::isfinite(lat) || !std::isfinite(lon) || std::abs(lat) > 90 || std::abs(lon) > 180) __builtin_trap();
    (void)telemetry::ToJson(*t.sample).dump();
  }
  (void)io::ParseTiffExif(data, size);
  return 0;
}
