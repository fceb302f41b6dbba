// `fmv3d klv FILE [-o out.json] [--telemetry]`: dumps every KLV packet of a media file's KLV data streams as
// JSON (layout close to KWIVER's klv_gold.json), or with --telemetry the per-packet telemetry samples;
// a summary (packets per stream, bad checksums, malformed packets) goes to stderr.
#include <fstream>
#include <iostream>

#include "command.h"
#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/telemetry/telemetry.h"

namespace fmv3d::app::cmd_klv {
namespace {

struct Options {
  std::string input;
  std::string output;
  bool telemetry = false;
};

void Run(const Options& o) {
  if (!std::filesystem::exists(o.input)) throw Error(o.input + ": no such file");
  telemetry::TelemetryStats stats;
  const auto packets = telemetry::ReadVideoKlv(o.input, &stats);
  nlohmann::json out = nlohmann::json::array();
  if (o.telemetry) {
    std::vector<telemetry::TelemetrySample> samples;
    for (const auto& p : packets)
      if (auto s = telemetry::SampleFromPacket(p)) samples.push_back(std::move(*s));
    for (const auto& s : samples) out.push_back(telemetry::ToJson(s));
  } else {
    for (const auto& p : packets) out.push_back(telemetry::klv::ToJson(p));
  }
  // KLV strings may hold any valid UTF-8 (and NULs); replace-on-error keeps the writer total anyway.
  const std::string text = out.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) + "\n";
  if (o.output.empty())
    std::cout << text;
  else
    core::WriteTextFile(o.output, text);

  const auto& k = stats.klv;
  if (stats.packets_per_stream.empty()) std::cerr << o.input << ": no KLV data stream (empty list written)\n";
  for (const auto& [idx, n] : stats.packets_per_stream)
    std::cerr << o.input << ": stream " << idx << ": " << n << " KLV packets\n";
  std::cerr << "packets kept: " << k.packets << ", bad checksum: " << k.bad_checksum << ", malformed: " << k.malformed
            << ", unknown keys: " << k.unknown_keys << ", items with unexpected length: " << k.bad_items
            << ", bytes skipped: " << k.skipped_bytes << "\n";
}

void Add(CLI::App& app) {
  auto* cmd = app.add_subcommand("klv", "Dump the MISB KLV metadata (ST 0601, EG0104, ST 0102) of a video as JSON");
  auto o = std::make_shared<Options>();
  cmd->add_option("FILE", o->input, "Video file (MPEG-TS with KLV data streams)")->required();
  cmd->add_option("-o,--output", o->output, "Write the JSON here instead of stdout");
  cmd->add_flag("--telemetry", o->telemetry, "Write the decoded telemetry samples instead of raw tag lists");
  cmd->callback([o] { Run(*o); });
}

const RegisterCommand reg(110, Add);

}  // namespace
}  // namespace fmv3d::app::cmd_klv
