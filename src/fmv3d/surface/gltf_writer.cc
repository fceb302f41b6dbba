#include "fmv3d/surface/gltf_writer.h"

// tinygltf is header-only: compiled here, without its bundled stb image codecs (OpenCV encodes the PNGs).
#define TINYGLTF_IMPLEMENTATION
#define TINYGLTF_NO_STB_IMAGE
#define TINYGLTF_NO_STB_IMAGE_WRITE
#define TINYGLTF_NO_EXTERNAL_IMAGE
#include <tiny_gltf.h>

#include <array>
#include <cstring>
#include <limits>
#include <unordered_map>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"

namespace fmv3d::surface {

namespace fs = std::filesystem;

namespace {

struct IndexTripleHash {
  size_t operator()(const std::array<int, 3>& k) const {
    uint64_t h = static_cast<uint32_t>(k[0]);
    h = h * 0x9E3779B97F4A7C15ULL ^ static_cast<uint32_t>(k[1]);
    h = h * 0x9E3779B97F4A7C15ULL ^ static_cast<uint32_t>(k[2]);
    return static_cast<size_t>(h ^ (h >> 29));
  }
};

// Appends bytes to the single buffer (4-byte aligned, as accessors require) and returns a buffer view.
int AddView(tinygltf::Model* model, const void* data, size_t bytes, int target) {
  auto& buf = model->buffers[0].data;
  while (buf.size() % 4) buf.push_back(0);
  tinygltf::BufferView view;
  view.buffer = 0;
  view.byteOffset = buf.size();
  view.byteLength = bytes;
  view.target = target;
  const auto* p = static_cast<const unsigned char*>(data);
  buf.insert(buf.end(), p, p + bytes);
  model->bufferViews.push_back(view);
  return static_cast<int>(model->bufferViews.size()) - 1;
}

int AddAccessor(tinygltf::Model* model, int view, int component, int type, size_t count, std::vector<double> min = {},
                std::vector<double> max = {}) {
  tinygltf::Accessor a;
  a.bufferView = view;
  a.componentType = component;
  a.type = type;
  a.count = count;
  a.minValues = std::move(min);
  a.maxValues = std::move(max);
  model->accessors.push_back(a);
  return static_cast<int>(model->accessors.size()) - 1;
}

}  // namespace

void WriteGlb(const io::TexturedMesh& mesh, const fs::path& path, const io::EncodedTextures* textures) {
  mesh.Validate();
  const io::EncodedTextures own = textures ? io::EncodedTextures{} : io::EncodeTextures(mesh);
  const io::EncodedTextures& pngs = textures ? *textures : own;
  io::CheckEncodedTextures(mesh, pngs, path);
  bool all_normals = !mesh.normals.empty();
  for (const auto& f : mesh.faces) {
    for (int k = 0; k < 3; ++k) {
      if (f.vt[k] < 0) throw Error(path.string() + ": every face needs texture coordinates for glTF");
      all_normals = all_normals && f.vn[k] >= 0;
    }
  }
  tinygltf::Model model;
  model.asset.version = "2.0";
  model.asset.generator = "fmv3d";
  model.buffers.resize(1);
  tinygltf::Mesh gmesh;
  gmesh.name = path.stem().string();

  const int num_materials = std::max<int>(1, static_cast<int>(mesh.materials.size()));
  std::vector<std::vector<uint32_t>> faces_of(num_materials);
  for (size_t i = 0; i < mesh.faces.size(); ++i)
    if (const int m = std::max(mesh.faces[i].material, 0); m < num_materials)
      faces_of[m].push_back(static_cast<uint32_t>(i));
  for (int m = 0; m < num_materials; ++m) {
    // Vertices of this material: one per distinct (position, uv, normal) index triple, numbered in face order.
    std::unordered_map<std::array<int, 3>, uint32_t, IndexTripleHash> index;
    index.reserve(faces_of[m].size() * 2);
    std::vector<float> pos, nrm, tex;
    std::vector<uint32_t> indices;
    for (const uint32_t fi : faces_of[m]) {
      const io::Face& f = mesh.faces[fi];
      for (int k = 0; k < 3; ++k) {
        const std::array<int, 3> key{f.v[k], f.vt[k], all_normals ? f.vn[k] : -1};
        auto [it, fresh] = index.emplace(key, static_cast<uint32_t>(index.size()));
        if (fresh) {
          const auto& v = mesh.vertices[f.v[k]];
          // glTF is +y up: rotate our z-up metres by -90 deg about x, (x, y, z) -> (x, z, -y).
          pos.insert(pos.end(), {static_cast<float>(v.x()), static_cast<float>(v.z()), static_cast<float>(-v.y())});
          const auto& t = mesh.uvs[f.vt[k]];
          tex.insert(tex.end(), {t.x(), 1.0f - t.y()});  // glTF: v = 0 at the top row
          if (all_normals) {
            const Eigen::Vector3f n = mesh.normals[f.vn[k]].normalized();
            nrm.insert(nrm.end(), {n.x(), n.z(), -n.y()});
          }
        }
        indices.push_back(it->second);
      }
    }
    if (indices.empty()) continue;
    std::vector<double> lo(3, std::numeric_limits<double>::max()), hi(3, std::numeric_limits<double>::lowest());
    for (size_t i = 0; i < pos.size(); ++i)
      lo[i % 3] = std::min(lo[i % 3], double(pos[i])), hi[i % 3] = std::max(hi[i % 3], double(pos[i]));
    const size_t nverts = pos.size() / 3;
    tinygltf::Primitive prim;
    prim.mode = TINYGLTF_MODE_TRIANGLES;
    prim.attributes["POSITION"] =
        AddAccessor(&model, AddView(&model, pos.data(), pos.size() * 4, TINYGLTF_TARGET_ARRAY_BUFFER),
                    TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, nverts, lo, hi);
    if (all_normals)
      prim.attributes["NORMAL"] =
          AddAccessor(&model, AddView(&model, nrm.data(), nrm.size() * 4, TINYGLTF_TARGET_ARRAY_BUFFER),
                      TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, nverts);
    prim.attributes["TEXCOORD_0"] =
        AddAccessor(&model, AddView(&model, tex.data(), tex.size() * 4, TINYGLTF_TARGET_ARRAY_BUFFER),
                    TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC2, nverts);
    prim.indices =
        AddAccessor(&model, AddView(&model, indices.data(), indices.size() * 4, TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER),
                    TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT, TINYGLTF_TYPE_SCALAR, indices.size());

    tinygltf::Material mat;
    mat.name = m < static_cast<int>(mesh.materials.size()) ? mesh.materials[m].name : "default";
    mat.pbrMetallicRoughness.metallicFactor = 0;
    mat.pbrMetallicRoughness.roughnessFactor = 1;
    mat.doubleSided = false;
    if (m < static_cast<int>(mesh.materials.size()) && !mesh.materials[m].texture.empty()) {
      const std::vector<uint8_t>& png = pngs[m];
      if (png.empty()) throw Error(path.string() + ": the texture of " + mat.name + " was not encoded");
      tinygltf::Image image;
      image.name = mat.name;
      image.mimeType = "image/png";
      image.bufferView = AddView(&model, png.data(), png.size(), 0);
      model.images.push_back(image);
      tinygltf::Texture texture;
      texture.source = static_cast<int>(model.images.size()) - 1;
      model.textures.push_back(texture);
      mat.pbrMetallicRoughness.baseColorTexture.index = static_cast<int>(model.textures.size()) - 1;
    } else if (m < static_cast<int>(mesh.materials.size())) {
      const auto& kd = mesh.materials[m].diffuse_bgr;
      mat.pbrMetallicRoughness.baseColorFactor = {kd.z(), kd.y(), kd.x(), 1.0};
    }
    model.materials.push_back(mat);
    prim.material = static_cast<int>(model.materials.size()) - 1;
    gmesh.primitives.push_back(prim);
  }
  if (gmesh.primitives.empty()) throw Error(path.string() + ": the mesh has no faces to write");
  model.meshes.push_back(gmesh);
  tinygltf::Node node;
  node.mesh = 0;
  model.nodes.push_back(node);
  tinygltf::Scene scene;
  scene.nodes.push_back(0);
  model.scenes.push_back(scene);
  model.defaultScene = 0;

  core::WriteAtomically(path, [&](const fs::path& tmp) {
    tinygltf::TinyGLTF writer;
    if (!writer.WriteGltfSceneToFile(&model, tmp.string(), true, true, false, true))
      throw Error(tmp.string() + ": cannot write glTF");
  });
}

}  // namespace fmv3d::surface
