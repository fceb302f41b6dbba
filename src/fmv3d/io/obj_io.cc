#include "fmv3d/io/obj_io.h"

#include <fmt/compile.h>
#include <fmt/format.h>
#include <tbb/parallel_for.h>

#include <charconv>
#include <cmath>
#include <fstream>
#include <functional>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <string_view>
#include <type_traits>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"

namespace fmv3d::io {
namespace fs = std::filesystem;
namespace {

bool IsBlank(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v'; }

// The next blank-separated token of `line` from *pos (empty at the end of the line).
std::string_view NextToken(std::string_view line, size_t* pos) {
  size_t i = *pos;
  while (i < line.size() && IsBlank(line[i])) ++i;
  size_t j = i;
  while (j < line.size() && !IsBlank(line[j])) ++j;
  *pos = j;
  return line.substr(i, j - i);
}

// The whole token as a finite number (a leading '+' allowed, as a stream reads it).
template <typename T>
bool ParseNumber(std::string_view token, T* value) {
  if (!token.empty() && token[0] == '+') token.remove_prefix(1);
  if (token.empty()) return false;
  const auto [end, ec] = std::from_chars(token.data(), token.data() + token.size(), *value);
  if (ec != std::errc() || end != token.data() + token.size()) return false;
  if constexpr (std::is_floating_point_v<T>) return std::isfinite(*value);
  return true;
}

template <typename T, int N>
bool ParseNumbers(std::string_view line, size_t* pos, T* values) {
  for (int k = 0; k < N; ++k)
    if (!ParseNumber(NextToken(line, pos), &values[k])) return false;
  return true;
}

// Resolves a 1-based (or negative, relative) OBJ index; returns -1 for an empty field.
int ResolveIndex(std::string_view s, size_t count, const std::function<std::string()>& where) {
  if (s.empty()) return -1;
  long i = 0;
  if (!ParseNumber(s, &i)) throw Error(where() + ": bad index '" + std::string(s) + "'");
  const long r = i > 0 ? i - 1 : static_cast<long>(count) + i;
  if (i == 0 || r < 0 || r >= static_cast<long>(count))
    throw Error(where() + ": index " + std::string(s) + " out of range");
  return static_cast<int>(r);
}

void ReadMtl(const fs::path& path, bool load_textures, TexturedMesh* mesh) {
  std::ifstream in(path);
  if (!in) throw Error(path.string() + ": cannot open material library");
  std::string line;
  Material* cur = nullptr;
  const size_t first = mesh->materials.size();  // this library's materials
  while (std::getline(in, line)) {
    std::istringstream ss(line);
    std::string key;
    if (!(ss >> key) || key[0] == '#') continue;
    if (key == "newmtl") {
      mesh->materials.emplace_back();
      cur = &mesh->materials.back();
      ss >> cur->name;
    } else if (cur && key == "Kd") {
      float r = 0.8f, g = 0.8f, b = 0.8f;
      ss >> r >> g >> b;
      cur->diffuse_bgr = {b, g, r};
    } else if (cur && key == "map_Kd") {
      std::string rest, last;
      while (ss >> rest) last = rest;  // options like -s come first; the file name is last
      cur->texture_file = last;
    }
  }
  if (!load_textures) return;
  // Atlas pages decoded side by side: a survey's model has several 4096² pages.
  tbb::parallel_for(first, mesh->materials.size(), [&](size_t m) {
    Material& mat = mesh->materials[m];
    if (mat.texture_file.empty()) return;
    const fs::path tex = path.parent_path() / mat.texture_file;
    if (!fs::exists(tex)) return;
    mat.texture = cv::imread(tex.string(), cv::IMREAD_COLOR);
    if (mat.texture.empty()) throw Error(tex.string() + ": cannot read texture");
  });
}

}  // namespace

TexturedMesh ReadObj(const fs::path& path, bool load_textures) {
  std::ifstream in(path);
  if (!in) throw Error(path.string() + ": cannot open");
  TexturedMesh mesh;
  std::string buffer;
  int material = -1;
  size_t line_no = 0;
  // Built only for a message: textured survey meshes are millions of lines.
  const std::function<std::string()> where = [&] { return path.string() + ":" + std::to_string(line_no); };
  std::vector<std::string> mtllibs;
  std::vector<std::pair<std::string, size_t>> pending_usemtl;  // (name, first face) resolved after MTL load
  std::vector<std::array<int, 3>> corners;
  while (std::getline(in, buffer)) {
    ++line_no;
    const std::string_view line = buffer;
    size_t pos = 0;
    const std::string_view key = NextToken(line, &pos);
    if (key.empty() || key[0] == '#') continue;
    if (key == "v") {
      Eigen::Vector3d v;
      if (!ParseNumbers<double, 3>(line, &pos, v.data())) throw Error(where() + ": bad vertex");
      mesh.vertices.push_back(v);
    } else if (key == "vt") {
      Eigen::Vector2f t;
      if (!ParseNumbers<float, 2>(line, &pos, t.data())) throw Error(where() + ": bad texture coordinate");
      mesh.uvs.push_back(t);
    } else if (key == "vn") {
      Eigen::Vector3f n;
      if (!ParseNumbers<float, 3>(line, &pos, n.data())) throw Error(where() + ": bad normal");
      mesh.normals.push_back(n);
    } else if (key == "f") {
      corners.clear();
      for (std::string_view tok = NextToken(line, &pos); !tok.empty(); tok = NextToken(line, &pos)) {
        std::array<std::string_view, 3> parts;
        size_t p = 0, begin = 0;
        for (size_t i = 0; i <= tok.size(); ++i) {
          if (i < tok.size() && tok[i] != '/') continue;
          if (p > 2) throw Error(where() + ": bad face corner '" + std::string(tok) + "'");
          parts[p++] = tok.substr(begin, i - begin);
          begin = i + 1;
        }
        corners.push_back({ResolveIndex(parts[0], mesh.vertices.size(), where),
                           ResolveIndex(parts[1], mesh.uvs.size(), where),
                           ResolveIndex(parts[2], mesh.normals.size(), where)});
        if (corners.back()[0] < 0) throw Error(where() + ": face corner without a vertex");
      }
      if (corners.size() < 3) throw Error(where() + ": face with fewer than 3 corners");
      for (size_t k = 1; k + 1 < corners.size(); ++k) {
        Face f;
        const std::array<int, 3>* c[3] = {&corners[0], &corners[k], &corners[k + 1]};
        for (int j = 0; j < 3; ++j) {
          f.v[j] = (*c[j])[0];
          f.vt[j] = (*c[j])[1];
          f.vn[j] = (*c[j])[2];
        }
        f.material = material;
        mesh.faces.push_back(f);
      }
    } else if (key == "mtllib") {
      mtllibs.emplace_back(NextToken(line, &pos));
    } else if (key == "usemtl") {
      pending_usemtl.emplace_back(std::string(NextToken(line, &pos)), mesh.faces.size());
      material = static_cast<int>(pending_usemtl.size()) - 1;  // placeholder, remapped below
    }
  }
  for (const auto& lib : mtllibs) ReadMtl(path.parent_path() / lib, load_textures, &mesh);
  // Remap usemtl placeholders to material indices by name.
  std::vector<int> remap(pending_usemtl.size(), -1);
  for (size_t i = 0; i < pending_usemtl.size(); ++i) {
    for (size_t m = 0; m < mesh.materials.size(); ++m)
      if (mesh.materials[m].name == pending_usemtl[i].first) remap[i] = static_cast<int>(m);
    if (remap[i] < 0) {
      Material m;
      m.name = pending_usemtl[i].first;
      mesh.materials.push_back(m);
      remap[i] = static_cast<int>(mesh.materials.size()) - 1;
    }
  }
  for (Face& f : mesh.faces)
    if (f.material >= 0) f.material = remap[f.material];
  mesh.Validate();
  return mesh;
}

EncodedTextures EncodeTextures(const TexturedMesh& mesh, int png_compression) {
  EncodedTextures pngs(mesh.materials.size());
  tbb::parallel_for(size_t{0}, mesh.materials.size(), [&](size_t m) {
    const Material& mat = mesh.materials[m];
    if (!mat.texture.empty() &&
        !cv::imencode(".png", mat.texture, pngs[m], {cv::IMWRITE_PNG_COMPRESSION, png_compression}))
      throw Error("cannot encode the texture of material '" + mat.name + "'");
  });
  return pngs;
}

void CheckEncodedTextures(const TexturedMesh& mesh, const EncodedTextures& textures, const fs::path& path) {
  if (textures.size() != mesh.materials.size())
    throw Error(path.string() + ": " + std::to_string(textures.size()) + " encoded textures for " +
                std::to_string(mesh.materials.size()) + " materials");
}

void WriteObj(const TexturedMesh& mesh, const fs::path& path, int png_compression) {
  WriteObj(mesh, path, EncodeTextures(mesh, png_compression));
}

void WriteObj(const TexturedMesh& mesh, const fs::path& path, const EncodedTextures& textures) {
  mesh.Validate();
  CheckEncodedTextures(mesh, textures, path);
  const std::string stem = path.stem().string();
  const fs::path dir = path.parent_path();
  if (!dir.empty()) core::EnsureDirectory(dir);
  std::string mtl = "# fmv3d material library\n";
  for (size_t m = 0; m < mesh.materials.size(); ++m) {
    const Material& mat = mesh.materials[m];
    const std::string name = mat.name.empty() ? fmt::format("material_{}", m) : mat.name;
    mtl += fmt::format("newmtl {}\nKa 0 0 0\nKd {:.6g} {:.6g} {:.6g}\nKs 0 0 0\nd 1\nillum 1\n", name,
                       mat.diffuse_bgr.z(), mat.diffuse_bgr.y(), mat.diffuse_bgr.x());
    if (!mat.texture.empty()) {
      const std::string tex_name = mat.texture_file.empty() ? fmt::format("{}_{}.png", stem, name) : mat.texture_file;
      mtl += "map_Kd ";
      mtl += tex_name;
      mtl += "\n";
      const fs::path tex = dir / tex_name;
      if (textures[m].empty()) throw Error(tex.string() + ": the texture was not encoded");
      core::WriteTextFile(tex, std::string_view(reinterpret_cast<const char*>(textures[m].data()), textures[m].size()));
    } else if (!mat.texture_file.empty()) {
      mtl += "map_Kd " + mat.texture_file + "\n";
    }
    mtl += "\n";
  }
  // Format strings compiled and written straight into the buffer: a textured survey mesh is millions of lines.
  fmt::memory_buffer buffer;
  auto out = fmt::appender(buffer);
  fmt::format_to(out, "# fmv3d mesh: {} vertices, {} faces, metres\nmtllib {}.mtl\n", mesh.vertices.size(),
                 mesh.faces.size(), stem);
  for (const auto& v : mesh.vertices)
    fmt::format_to(out, FMT_COMPILE("v {:.17g} {:.17g} {:.17g}\n"), v.x(), v.y(), v.z());
  for (const auto& t : mesh.uvs) fmt::format_to(out, FMT_COMPILE("vt {:.9g} {:.9g}\n"), t.x(), t.y());
  for (const auto& n : mesh.normals) fmt::format_to(out, FMT_COMPILE("vn {:.9g} {:.9g} {:.9g}\n"), n.x(), n.y(), n.z());
  int cur_material = -2;
  for (const Face& f : mesh.faces) {
    if (f.material != cur_material) {
      cur_material = f.material;
      if (f.material >= 0) {
        const auto& name = mesh.materials[f.material].name;
        fmt::format_to(out, "usemtl {}\n", name.empty() ? fmt::format("material_{}", f.material) : name);
      }
    }
    buffer.push_back('f');
    for (int k = 0; k < 3; ++k) {
      fmt::format_to(out, FMT_COMPILE(" {}"), f.v[k] + 1);
      if (f.vt[k] >= 0 || f.vn[k] >= 0) {
        buffer.push_back('/');
        if (f.vt[k] >= 0) fmt::format_to(out, FMT_COMPILE("{}"), f.vt[k] + 1);
        if (f.vn[k] >= 0) fmt::format_to(out, FMT_COMPILE("/{}"), f.vn[k] + 1);
      }
    }
    buffer.push_back('\n');
  }
  core::WriteTextFile(dir / (stem + ".mtl"), mtl);
  core::WriteTextFile(path, std::string_view(buffer.data(), buffer.size()));
}

}  // namespace fmv3d::io
