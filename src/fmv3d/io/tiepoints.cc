#include "fmv3d/io/tiepoints.h"

#include <cmath>
#include <set>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"

namespace fmv3d::io {
namespace {

using Json = nlohmann::json;

// Reads j[key] of the wanted kind; a missing or mistyped value adds "<where>: <what>" to errors.
class FieldReader {
 public:
  FieldReader(const Json& j, std::string where, std::vector<std::string>* errors)
      : j_(j), where_(std::move(where)), errors_(errors) {}

  std::string String(const char* key, bool required = true) const {
    if (!j_.contains(key)) {
      if (required) Fail(std::string("\"") + key + "\" is missing");
      return {};
    }
    const Json& v = j_.at(key);
    if (!v.is_string()) {
      Fail(std::string("\"") + key + "\" must be a string");
      return {};
    }
    return v.get<std::string>();
  }
  double Number(const char* key) const {
    if (!j_.contains(key)) {
      Fail(std::string("\"") + key + "\" is missing");
      return 0;
    }
    const Json& v = j_.at(key);
    if (!v.is_number()) {
      Fail(std::string("\"") + key + "\" must be a number");
      return 0;
    }
    const double d = v.get<double>();
    if (!std::isfinite(d)) Fail(std::string("\"") + key + "\" must be finite");
    return d;
  }
  uint32_t Index(const char* key) const {
    if (!j_.contains(key)) {
      Fail(std::string("\"") + key + "\" is missing");
      return 0;
    }
    const Json& v = j_.at(key);
    if (!v.is_number_integer() || v.get<int64_t>() < 0 || v.get<int64_t>() > int64_t{UINT32_MAX}) {
      Fail(std::string("\"") + key + "\" must be a keypoint index (an integer ≥ 0)");
      return 0;
    }
    return static_cast<uint32_t>(v.get<int64_t>());
  }
  // An array (empty when absent).
  const Json* Array(const char* key) const {
    if (!j_.contains(key)) return nullptr;
    if (!j_.at(key).is_array()) {
      Fail(std::string("\"") + key + "\" must be an array");
      return nullptr;
    }
    return &j_.at(key);
  }
  void Fail(const std::string& what) const { errors_->push_back(where_ + ": " + what); }

 private:
  const Json& j_;
  std::string where_;
  std::vector<std::string>* errors_;
};

std::string Quoted(const std::string& s) { return "\"" + s + "\""; }

ImagePoint ReadPoint(const Json& j, const std::string& where, std::vector<std::string>* errors) {
  ImagePoint p;
  if (!j.is_object()) {
    errors->push_back(where + ": must be an object {\"frame\", \"x\", \"y\"}");
    return p;
  }
  FieldReader r(j, where, errors);
  p.frame = r.String("frame");
  if (j.contains("frame") && j.at("frame").is_string() && p.frame.empty()) r.Fail("\"frame\" is empty");
  p.x = r.Number("x");
  p.y = r.Number("y");
  return p;
}

void CheckPoint(const ImagePoint& p, const FrameTable& frames, const std::string& where,
                std::vector<std::string>* errors) {
  const auto it = frames.find(p.frame);
  if (it == frames.end()) {
    errors->push_back(where + ": frame " + Quoted(p.frame) + " is not in frames/frames.json");
    return;
  }
  const FrameLimits& f = it->second;
  if (!(p.x >= 0 && p.x <= f.width && p.y >= 0 && p.y <= f.height)) {
    char buf[160];
    std::snprintf(buf, sizeof buf, "(%.2f, %.2f) is outside frame %s (%dx%d)", p.x, p.y, Quoted(p.frame).c_str(),
                  f.width, f.height);
    errors->push_back(where + ": " + buf);
  }
}

}  // namespace

FrameTable FrameTableOf(const FramesIndex& index) {
  FrameTable table;
  for (const auto& f : index.frames) {
    FrameLimits l;
    if (const auto* c = index.FindCamera(f.camera_id)) {
      l.width = c->camera.width;
      l.height = c->camera.height;
    }
    table[f.name] = l;
  }
  return table;
}

TiePoints TiePointsFromJson(const Json& j, std::vector<std::string>* errors) {
  TiePoints out;
  if (!j.is_object()) {
    errors->push_back("must be a JSON object with \"format\": \"fmv3d-tiepoints\"");
    return out;
  }
  FieldReader top(j, "tiepoints", errors);
  if (!j.contains("format") || !j.at("format").is_string() || j.at("format").get<std::string>() != kTiePointsFormat) {
    errors->push_back(std::string("\"format\" must be \"") + kTiePointsFormat + "\"");
    return out;
  }
  if (!j.contains("version") || !j.at("version").is_number_integer() ||
      j.at("version").get<int64_t>() != kTiePointsVersion) {
    errors->push_back("\"version\" must be " + std::to_string(kTiePointsVersion) +
                      " (this fmv3d reads version 1 only)");
    return out;
  }
  std::set<std::string> ids;
  auto check_id = [&](const std::string& id, const std::string& where) {
    if (id.empty()) {
      errors->push_back(where + ": \"id\" is empty");
    } else if (!ids.insert(id).second) {
      errors->push_back(where + ": duplicate id " + Quoted(id));
    }
  };
  if (const Json* arr = top.Array("tie_points")) {
    for (size_t i = 0; i < arr->size(); ++i) {
      const Json& t = (*arr)[i];
      std::string where = "tie point " + std::to_string(i + 1);
      if (!t.is_object()) {
        errors->push_back(where + ": must be an object {\"id\", \"observations\"}");
        continue;
      }
      FieldReader r(t, where, errors);
      TiePoint tp;
      tp.id = r.String("id");
      if (t.contains("id") && t.at("id").is_string()) {
        where = "tie point " + Quoted(tp.id);
        check_id(tp.id, where);
      }
      tp.label = r.String("label", false);
      const Json* obs = FieldReader(t, where, errors).Array("observations");
      if (!t.contains("observations")) errors->push_back(where + ": \"observations\" is missing");
      std::set<std::string> frames;
      if (obs) {
        for (size_t k = 0; k < obs->size(); ++k) {
          const std::string ow = where + ", observation " + std::to_string(k + 1);
          tp.observations.push_back(ReadPoint((*obs)[k], ow, errors));
          const std::string& fr = tp.observations.back().frame;
          if (!fr.empty() && !frames.insert(fr).second)
            errors->push_back(ow + ": a second observation in frame " + Quoted(fr) + " (one per frame)");
        }
        if (obs->size() < 2)
          errors->push_back(where + ": has " + std::to_string(obs->size()) +
                            " observation(s); a tie point needs ≥ 2 (in different frames)");
      }
      out.tie_points.push_back(std::move(tp));
    }
  }
  if (const Json* arr = top.Array("keypoints")) {
    for (size_t i = 0; i < arr->size(); ++i) {
      const Json& t = (*arr)[i];
      std::string where = "keypoint " + std::to_string(i + 1);
      if (!t.is_object()) {
        errors->push_back(where + ": must be an object {\"id\", \"frame\", \"x\", \"y\"}");
        continue;
      }
      ManualKeypoint kp;
      kp.id = FieldReader(t, where, errors).String("id");
      if (t.contains("id") && t.at("id").is_string()) {
        where = "keypoint " + Quoted(kp.id);
        check_id(kp.id, where);
      }
      kp.label = FieldReader(t, where, errors).String("label", false);
      kp.point = ReadPoint(t, where, errors);
      out.keypoints.push_back(std::move(kp));
    }
  }
  if (const Json* arr = top.Array("deleted_matches")) {
    for (size_t i = 0; i < arr->size(); ++i) {
      const Json& t = (*arr)[i];
      const std::string where = "deleted match " + std::to_string(i + 1);
      if (!t.is_object()) {
        errors->push_back(where + ": must be an object {\"frame1\", \"frame2\", \"feature1\", \"feature2\"}");
        continue;
      }
      FieldReader r(t, where, errors);
      DeletedMatch d;
      d.frame1 = r.String("frame1");
      d.frame2 = r.String("frame2");
      d.feature1 = r.Index("feature1");
      d.feature2 = r.Index("feature2");
      if (!d.frame1.empty() && d.frame1 == d.frame2) r.Fail("frame1 and frame2 are the same frame");
      out.deleted_matches.push_back(std::move(d));
    }
  }
  return out;
}

TiePoints ParseTiePoints(const std::string& text, std::vector<std::string>* errors) {
  Json j;
  try {
    j = Json::parse(text);
  } catch (const Json::exception& e) {
    errors->push_back(std::string("not valid JSON (") + e.what() + ")");
    return {};
  }
  return TiePointsFromJson(j, errors);
}

Json TiePointsToJson(const TiePoints& t) {
  auto point = [](const ImagePoint& p) { return Json{{"frame", p.frame}, {"x", p.x}, {"y", p.y}}; };
  Json tps = Json::array(), kps = Json::array(), dels = Json::array();
  for (const auto& tp : t.tie_points) {
    Json obs = Json::array();
    for (const auto& o : tp.observations) obs.push_back(point(o));
    Json e = {{"id", tp.id}};
    if (!tp.label.empty()) e["label"] = tp.label;
    e["observations"] = obs;
    tps.push_back(e);
  }
  for (const auto& kp : t.keypoints) {
    Json e = point(kp.point);
    e["id"] = kp.id;
    if (!kp.label.empty()) e["label"] = kp.label;
    kps.push_back(e);
  }
  for (const auto& d : t.deleted_matches)
    dels.push_back({{"frame1", d.frame1}, {"frame2", d.frame2}, {"feature1", d.feature1}, {"feature2", d.feature2}});
  return {{"format", kTiePointsFormat},
          {"version", kTiePointsVersion},
          {"tie_points", tps},
          {"keypoints", kps},
          {"deleted_matches", dels}};
}

void CheckTiePoints(const TiePoints& t, const FrameTable& frames, std::vector<std::string>* errors) {
  for (const auto& tp : t.tie_points)
    for (size_t k = 0; k < tp.observations.size(); ++k)
      CheckPoint(tp.observations[k], frames, "tie point " + Quoted(tp.id) + ", observation " + std::to_string(k + 1),
                 errors);
  for (const auto& kp : t.keypoints) CheckPoint(kp.point, frames, "keypoint " + Quoted(kp.id), errors);
  for (size_t i = 0; i < t.deleted_matches.size(); ++i) {
    const auto& d = t.deleted_matches[i];
    const std::string where = "deleted match " + std::to_string(i + 1);
    for (const auto& [frame, index] : {std::pair{d.frame1, d.feature1}, std::pair{d.frame2, d.feature2}}) {
      const auto it = frames.find(frame);
      if (it == frames.end()) {
        errors->push_back(where + ": frame " + Quoted(frame) + " is not in frames/frames.json");
      } else if (index >= it->second.num_keypoints) {
        errors->push_back(where + ": feature " + std::to_string(index) + " of frame " + Quoted(frame) +
                          " does not exist (it has " + std::to_string(it->second.num_keypoints) + " keypoints)");
      }
    }
  }
}

std::string JoinErrors(const std::vector<std::string>& errors, size_t max_shown) {
  std::string s;
  for (size_t i = 0; i < errors.size() && i < max_shown; ++i) s += (i ? "; " : "") + errors[i];
  if (errors.size() > max_shown) s += "; (" + std::to_string(errors.size() - max_shown) + " more)";
  return s;
}

TiePoints ReadTiePoints(const std::filesystem::path& path, const FrameTable* frames) {
  std::vector<std::string> errors;
  TiePoints t = ParseTiePoints(core::ReadTextFile(path), &errors);
  if (errors.empty() && frames) CheckTiePoints(t, *frames, &errors);
  if (!errors.empty()) throw Error(path.string() + ": " + JoinErrors(errors));
  return t;
}

void WriteTiePoints(const TiePoints& t, const std::filesystem::path& path, const FrameTable* frames) {
  const Json j = TiePointsToJson(t);
  // The written form is read back through the parser, so whatever the writer accepts the reader accepts too.
  std::vector<std::string> errors;
  const TiePoints again = TiePointsFromJson(j, &errors);
  if (errors.empty() && frames) CheckTiePoints(again, *frames, &errors);
  if (!errors.empty()) throw Error(path.string() + ": not saved: " + JoinErrors(errors));
  core::EnsureDirectory(path.parent_path().empty() ? std::filesystem::path(".") : path.parent_path());
  core::WriteTextFile(path, j.dump(2) + "\n");
}

}  // namespace fmv3d::io
