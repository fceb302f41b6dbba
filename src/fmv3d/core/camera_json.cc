#include "fmv3d/core/camera_json.h"

namespace fmv3d::core {

void IntrinsicsFromJson(const nlohmann::json& j, Camera* c) {
  c->f = j.at("f").get<double>();
  c->aspect = j.value("aspect", 1.0);
  c->u0 = j.value("u0", c->width * 0.5);
  c->v0 = j.value("v0", c->height * 0.5);
  c->k1 = j.value("k1", 0.0);
  c->k2 = j.value("k2", 0.0);
  c->p1 = j.value("p1", 0.0);
  c->p2 = j.value("p2", 0.0);
}

nlohmann::json IntrinsicsToJson(const Camera& c) {
  return {{"f", c.f},   {"aspect", c.aspect}, {"u0", c.u0}, {"v0", c.v0},
          {"k1", c.k1}, {"k2", c.k2},         {"p1", c.p1}, {"p2", c.p2}};
}

nlohmann::json CameraToJson(const Camera& c) {
  nlohmann::json j = IntrinsicsToJson(c);
  j["width"] = c.width;
  j["height"] = c.height;
  return j;
}

}  // namespace fmv3d::core
