// Telemetry of a still photo: the EXIF GPS IFD and DJI's XMP (`drone-dji:` namespace) turned into the same
// TelemetrySample that KLV and SRT fill (time 0, as a photo's frame timestamp), so pair selection, priors,
// georef, DSM and ortho use photos as they use video.
//
// Fields (telemetry.h):
//   sensor_latitude/longitude   EXIF GPSLatitude/GPSLongitude (signed by their refs), else drone-dji:GpsLatitude/
//                               GpsLongitude (DJI also spells it GpsLongtitude)
//   altitude                    drone-dji:AbsoluteAltitude when present (more digits than EXIF), else EXIF
//                               GPSAltitude (signed by GPSAltitudeRef). Its datum: see AltitudeDatum below;
//                               the value goes to sensor_altitude_msl or sensor_altitude_hae accordingly, so the
//                               frame telemetry states the datum by its field name.
//   sensor_relative_altitude    drone-dji:RelativeAltitude (above the take-off point)
//   gimbal_yaw/pitch/roll       drone-dji:GimbalYawDegree/PitchDegree/RollDegree (absolute, attitude.h)
//   platform_heading/pitch/roll drone-dji:FlightYawDegree/PitchDegree/RollDegree; with the gimbal angles also the
//                               ST 0601 sensor-relative angles of the same camera rotation (attitude.h), so georef
//                               reads the full attitude chain as it does from KLV
//   gps_dop, gps_fix            EXIF GPSDOP, GPSMeasureMode ('2'/'3'); GPSStatus 'V' (void) → gps_fix 0
//   horizontal/vertical_accuracy EXIF GPSHPositioningError; DJI RTK: max(RtkStdLon, RtkStdLat), RtkStdHgt (m, 1σ)
//   rtk_flag                    drone-dji:RtkFlag (0 none, 16 single point, 34 float, 50 fixed)
//   unix_time_us                EXIF GPSDateStamp + GPSTimeStamp (UTC)
#pragma once

#include <cstddef>
#include <optional>
#include <string>

#include "fmv3d/io/exif.h"
#include "fmv3d/telemetry/fix_quality.h"
#include "fmv3d/telemetry/telemetry.h"

namespace fmv3d::telemetry {

// The drone-dji: fields we use, as numbers. Accepts both XMP serialisations (attributes
// drone-dji:Name="value" and elements <drone-dji:Name>value</drone-dji:Name>). Untrusted text: bounded scans,
// a field that is not a finite number is counted in `malformed` and left empty.
struct DjiXmp {
  std::optional<double> gimbal_yaw, gimbal_pitch, gimbal_roll;
  std::optional<double> flight_yaw, flight_pitch, flight_roll;
  std::optional<double> relative_altitude, absolute_altitude;
  std::optional<double> latitude, longitude;
  std::optional<double> rtk_flag, rtk_std_lon, rtk_std_lat, rtk_std_hgt;
  size_t fields = 0;     // drone-dji: fields seen (any name)
  size_t malformed = 0;  // of the fields above, those whose value is not a finite number
};
DjiXmp ParseDjiXmp(const std::string& xmp);
// An XMP packet with the set fields as drone-dji: attributes, as DJI writes them (for test data).
std::string EncodeDjiXmp(const DjiXmp& dji);

// The vertical datum of a photo's altitude. EXIF 2.32 defines GPSAltitude as height above sea level, and DJI
// documents AbsoluteAltitude as MSL for its consumer and enterprise models, so kAuto reads both as MSL; some
// makers (phones writing raw GNSS heights, RTK setups configured for ellipsoidal output) write ellipsoidal
// heights: the user states it with kEllipsoid (`fmv3d frames --altitude-datum ellipsoid`).
enum class AltitudeDatum { kAuto, kMsl, kEllipsoid };
// "auto" | "msl" | "ellipsoid"; throws fmv3d::Error on anything else.
AltitudeDatum ParseAltitudeDatum(const std::string& s);

struct PhotoTelemetryOptions {
  AltitudeDatum altitude_datum = AltitudeDatum::kAuto;
  FixQualityOptions fix;
};

struct PhotoTelemetry {
  std::optional<TelemetrySample> sample;               // set when the photo has a position that passed ScreenFix
  FixRejection rejection = FixRejection::kNoPosition;  // kNone when `sample` is set
  DjiXmp dji;                                          // what the XMP held (for dumps and warnings)
};

PhotoTelemetry TelemetryFromPhoto(const io::ExifInfo& exif, const PhotoTelemetryOptions& options);

}  // namespace fmv3d::telemetry
