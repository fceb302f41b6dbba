// EXIF writer (the inverse of exif.h, for test data: `fmv3d synth --exif-gps`): a little-endian TIFF structure
// with IFD0 (Make, Model), the EXIF IFD (DateTimeOriginal, FocalLength, FocalLengthIn35mmFilm, FocalPlaneX/YResolution
// with its unit, PixelXDimension) and the GPS IFD
// (version 2.3, latitude/longitude as degrees/minutes/seconds rationals with their refs, altitude with its ref,
// time and date stamps, status, measure mode, DOP, map datum, horizontal positioning error), each written only
// when set; and its insertion, with an XMP packet, into a JPEG as APP1 segments right after SOI.
//
// Precision: seconds of arc to 1e-4 (3 mm), altitude to 1 mm, DOP and positioning error to 0.01.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "fmv3d/io/exif.h"

namespace fmv3d::io {

// Throws fmv3d::Error when a value cannot be encoded (latitude beyond ±90°, non-finite numbers).
std::vector<uint8_t> EncodeTiffExif(const ExifInfo& exif);

// The JPEG with an "Exif" APP1 segment holding `tiff` (when not empty) and an XMP APP1 segment holding `xmp`
// (when not empty) inserted after its SOI marker. Throws fmv3d::Error when the input is not a JPEG or a segment
// would exceed the 64 KiB a JPEG segment can hold.
std::vector<uint8_t> InsertJpegMetadata(const std::vector<uint8_t>& jpeg, const std::vector<uint8_t>& tiff,
                                        const std::string& xmp);

}  // namespace fmv3d::io
