// `fmv3d telemetry INPUT [-o out.json] [--altitude-datum auto|msl|ellipsoid]`: dumps the telemetry of a photo
// (EXIF GPS, DJI XMP), a video (KLV, GoPro GPMF, DJI SRT beside it), an .SRT file or a raw GPMF payload as
// JSON — the per-frame samples `fmv3d frames` uses, and what each reader saw (see telemetry_dump.h).
#include <iostream>

#include "command.h"
#include "fmv3d/core/files.h"
#include "fmv3d/telemetry/telemetry_dump.h"

namespace fmv3d::app::cmd_telemetry {
namespace {

struct Options {
  std::string input, output, altitude_datum = "auto";
  telemetry::DumpOptions dump;
};

void Add(CLI::App& app) {
  auto* cmd = app.add_subcommand("telemetry",
                                 "Dump the telemetry of a photo (EXIF GPS, DJI XMP), a video (KLV, GoPro GPMF, DJI "
                                 "SRT), an .SRT or a raw GPMF payload as JSON");
  auto o = std::make_shared<Options>();
  cmd->add_option("INPUT", o->input, "Photo, video, .SRT or raw GPMF payload")->required();
  cmd->add_option("-o,--output", o->output, "Write the JSON here instead of stdout");
  cmd->add_option("--altitude-datum", o->altitude_datum,
                  "Datum of photo altitudes: auto (EXIF and DJI: mean sea level), msl, ellipsoid")
      ->check(CLI::IsMember({"auto", "msl", "ellipsoid"}))
      ->capture_default_str();
  cmd->add_option("--max-dop", o->dump.photo.fix.max_dop, "Drop GPS fixes with a larger DOP")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--max-accuracy", o->dump.photo.fix.max_horizontal_accuracy,
                  "Drop GPS fixes stating a worse horizontal accuracy, metres")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->callback([o] {
    o->dump.photo.altitude_datum = telemetry::ParseAltitudeDatum(o->altitude_datum);
    const nlohmann::json j = telemetry::DumpTelemetry(o->input, o->dump);
    const std::string text = j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) + "\n";
    if (o->output.empty())
      std::cout << text;
    else
      core::WriteTextFile(o->output, text);
  });
}

const RegisterCommand reg(111, Add);

}  // namespace
}  // namespace fmv3d::app::cmd_telemetry
