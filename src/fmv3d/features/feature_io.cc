#include "fmv3d/features/feature_io.h"

#include <unistd.h>

#include <cstring>
#include <fstream>
#include <iterator>
#include <memory>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"

namespace fmv3d::features {
namespace fs = std::filesystem;

namespace {

constexpr char kFeatMagic[8] = {'F', 'M', 'V', '3', 'D', 'F', 'E', 'A'};
constexpr char kFeatEnd[8] = {'F', 'E', 'A', '-', 'E', 'N', 'D', '.'};
constexpr char kMatMagic[8] = {'F', 'M', 'V', '3', 'D', 'M', 'A', 'T'};
constexpr char kMatEnd[8] = {'M', 'A', 'T', '-', 'E', 'N', 'D', '.'};

class Writer {
 public:
  void Bytes(const void* p, size_t n) {
    const char* c = static_cast<const char*>(p);
    buf_.insert(buf_.end(), c, c + n);
  }
  template <typename T>
  void Put(const T& v) {
    Bytes(&v, sizeof(T));
  }
  void Mat(const Eigen::Matrix3d& m) {
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) Put<double>(m(r, c));
  }
  void Save(const fs::path& path) {
    core::WriteAtomically(path, [&](const fs::path& tmp) {
      std::ofstream out(tmp, std::ios::binary);
      out.write(buf_.data(), static_cast<std::streamsize>(buf_.size()));
      if (!out) throw Error(path.string() + ": cannot write");
    });
  }
  std::vector<char> buf_;
};

// The checks every reader of our binary formats makes, whatever holds the bytes: Derived supplies
// Bytes(p, n, what), Remaining() and path(); counts, magic and end markers are checked the same way for both.
template <typename Derived>
class CheckedReader {
 public:
  template <typename T>
  T Get(const char* what) {
    T v;
    self().Bytes(&v, sizeof(T), what);
    return v;
  }
  Eigen::Matrix3d Mat(const char* what) {
    double v[9];
    self().Bytes(v, sizeof v, what);
    Eigen::Matrix3d m;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) m(r, c) = v[3 * r + c];
    return m;
  }
  void Magic(const char (&magic)[8], const char* kind) {
    char m[8];
    if (self().Remaining() < 8) throw Error(self().path().string() + ": too short to be " + kind);
    self().Bytes(m, 8, "magic");
    if (std::memcmp(m, magic, 8) != 0) throw Error(self().path().string() + ": not " + kind + " (wrong magic)");
  }
  void End(const char (&end)[8]) {
    char m[8];
    self().Bytes(m, 8, "end marker");
    if (std::memcmp(m, end, 8) != 0) throw Error(self().path().string() + ": corrupt file (bad end marker)");
    if (self().Remaining() != 0)
      throw Error(self().path().string() + ": corrupt file (trailing bytes after end marker)");
  }
  // Fails early with a clear message when a count cannot fit in the rest of the file (instead of trying to
  // allocate gigabytes for a corrupt count).
  void CheckFits(uint64_t count, uint64_t bytes_each, const char* what) {
    if (bytes_each > 0 && count > self().Remaining() / bytes_each)
      throw Error(self().path().string() + ": truncated or corrupt file (" + std::to_string(count) + " " + what +
                  " do not fit in the remaining " + std::to_string(self().Remaining()) + " bytes)");
  }

 protected:
  void CheckAvailable(uint64_t n, const char* what) {
    if (n > self().Remaining())
      throw Error(self().path().string() + ": truncated file (" + what + " needs " + std::to_string(n) + " bytes, " +
                  std::to_string(self().Remaining()) + " left)");
  }

 private:
  Derived& self() { return static_cast<Derived&>(*this); }
};

// A whole file in memory.
class Reader : public CheckedReader<Reader> {
 public:
  explicit Reader(const fs::path& path) : path_(path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw Error(path.string() + ": cannot open (missing file?)");
    buf_.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  size_t Remaining() const { return buf_.size() - pos_; }
  void Bytes(void* p, size_t n, const char* what) {
    CheckAvailable(n, what);
    std::memcpy(p, buf_.data() + pos_, n);
    pos_ += n;
  }
  void Skip(size_t n, const char* what) {
    CheckAvailable(n, what);
    pos_ += n;
  }
  const fs::path& path() const { return path_; }

 private:
  fs::path path_;
  std::vector<char> buf_;
  size_t pos_ = 0;
};

// An open file read piece by piece instead of whole.
class StreamReader : public CheckedReader<StreamReader> {
 public:
  explicit StreamReader(const fs::path& path) : path_(path), in_(path, std::ios::binary) {
    if (!in_) throw Error(path.string() + ": cannot open (missing file?)");
    in_.seekg(0, std::ios::end);
    size_ = static_cast<uint64_t>(in_.tellg());
    in_.seekg(0);
  }
  uint64_t Remaining() const { return size_ - pos_; }
  uint64_t position() const { return pos_; }
  void Seek(uint64_t pos) {
    in_.clear();
    in_.seekg(static_cast<std::streamoff>(pos));
    pos_ = pos;
  }
  void Bytes(void* p, size_t n, const char* what) {
    CheckAvailable(n, what);
    in_.read(static_cast<char*>(p), static_cast<std::streamsize>(n));
    if (!in_) throw Error(path_.string() + ": cannot read");
    pos_ += n;
  }
  void Skip(size_t n, const char* what) {
    CheckAvailable(n, what);
    Seek(pos_ + n);
  }
  const fs::path& path() const { return path_; }

 private:
  fs::path path_;
  std::ifstream in_;
  uint64_t size_ = 0, pos_ = 0;
};

void PutPair(Writer* w, const VerifiedPair& p) {
  w->Put<uint32_t>(p.image_id1);
  w->Put<uint32_t>(p.image_id2);
  w->Put<uint8_t>(static_cast<uint8_t>(p.geometry));
  w->Put<uint8_t>(p.has_pose ? 1 : 0);
  w->Put<uint32_t>(p.num_putative);
  w->Put<uint32_t>(p.num_inliers_F);
  w->Put<uint32_t>(p.num_inliers_E);
  w->Put<uint32_t>(p.num_inliers_H);
  w->Mat(p.F);
  w->Mat(p.E);
  w->Mat(p.H);
  w->Mat(p.R);
  for (int i = 0; i < 3; ++i) w->Put<double>(p.t[i]);
  w->Put<double>(p.median_triangulation_angle_deg);
  w->Put<uint32_t>(static_cast<uint32_t>(p.inliers.size()));
  for (const auto& m : p.inliers) {
    w->Put<uint32_t>(m.idx1);
    w->Put<uint32_t>(m.idx2);
  }
}

// The match file's header up to the pair count; returns the count, checked against the file's size.
template <typename R>
uint32_t GetMatchHeader(R* r, const fs::path& path) {
  r->Magic(kMatMagic, "an fmv3d match file");
  const auto version = r->template Get<uint32_t>("version");
  if (version != kMatchFileVersion)
    throw Error(path.string() + ": match file version " + std::to_string(version) + " not supported (expected " +
                std::to_string(kMatchFileVersion) + "; re-run `fmv3d match`)");
  const uint32_t num_pairs = r->template Get<uint32_t>("pair count");
  constexpr uint64_t kPairHeader = 4 * 2 + 2 + 4 * 4 + 8 * (9 * 4 + 3 + 1) + 4;
  r->CheckFits(num_pairs, kPairHeader, "pairs");
  return num_pairs;
}

// One pair; its inliers are skipped (not kept) unless `inliers`.
template <typename R>
VerifiedPair GetPair(R* r, const fs::path& path, bool inliers) {
  VerifiedPair p;
  p.image_id1 = r->template Get<uint32_t>("pair");
  p.image_id2 = r->template Get<uint32_t>("pair");
  const auto geometry = r->template Get<uint8_t>("pair");
  if (geometry > static_cast<uint8_t>(PairGeometry::kPlanarOrRotation))
    throw Error(path.string() + ": corrupt file (pair geometry code " + std::to_string(geometry) + ")");
  p.geometry = static_cast<PairGeometry>(geometry);
  p.has_pose = r->template Get<uint8_t>("pair") != 0;
  p.num_putative = r->template Get<uint32_t>("pair");
  p.num_inliers_F = r->template Get<uint32_t>("pair");
  p.num_inliers_E = r->template Get<uint32_t>("pair");
  p.num_inliers_H = r->template Get<uint32_t>("pair");
  p.F = r->Mat("pair");
  p.E = r->Mat("pair");
  p.H = r->Mat("pair");
  p.R = r->Mat("pair");
  for (int i = 0; i < 3; ++i) p.t[i] = r->template Get<double>("pair");
  p.median_triangulation_angle_deg = r->template Get<double>("pair");
  const uint32_t m = r->template Get<uint32_t>("inlier count");
  r->CheckFits(m, 8, "inlier matches");
  if (inliers) {
    p.inliers.resize(m);
    for (auto& fm : p.inliers) {
      fm.idx1 = r->template Get<uint32_t>("inlier");
      fm.idx2 = r->template Get<uint32_t>("inlier");
    }
  } else {
    r->Skip(size_t{m} * 8, "inlier matches");
  }
  if (p.image_id1 == 0 || p.image_id1 >= p.image_id2)
    throw Error(path.string() + ": corrupt file (pair " + std::to_string(p.image_id1) + "-" +
                std::to_string(p.image_id2) + " violates 0 < image_id1 < image_id2)");
  return p;
}

}  // namespace

void WriteFeatures(const FeatureSet& f, const fs::path& path) {
  const size_t n = f.keypoints.size();
  if (static_cast<size_t>(f.descriptors.rows()) != n || f.colors.size() != n)
    throw Error(path.string() + ": inconsistent feature set (" + std::to_string(n) + " keypoints, " +
                std::to_string(f.descriptors.rows()) + " descriptors, " + std::to_string(f.colors.size()) +
                " colours)");
  Writer w;
  w.Bytes(kFeatMagic, 8);
  w.Put<uint32_t>(kFeatureFileVersion);
  w.Put<int32_t>(f.width);
  w.Put<int32_t>(f.height);
  w.Put<uint32_t>(static_cast<uint32_t>(n));
  w.Put<uint32_t>(static_cast<uint32_t>(f.image_name.size()));
  w.Bytes(f.image_name.data(), f.image_name.size());
  w.Put<double>(f.contrast_threshold);
  for (const auto& k : f.keypoints) {
    w.Put<float>(k.x);
    w.Put<float>(k.y);
    w.Put<float>(k.scale);
    w.Put<float>(k.orientation);
  }
  if (n > 0) w.Bytes(f.descriptors.data(), n * 128);
  for (const auto& c : f.colors) w.Bytes(c.data(), 3);
  w.Bytes(kFeatEnd, 8);
  w.Save(path);
}

FeatureSet ReadFeatures(const fs::path& path, bool descriptors) {
  Reader r(path);
  r.Magic(kFeatMagic, "an fmv3d feature file");
  const auto version = r.Get<uint32_t>("version");
  if (version != 1 && version != kFeatureFileVersion)
    throw Error(path.string() + ": feature file version " + std::to_string(version) + " not supported (expected " +
                std::to_string(kFeatureFileVersion) + "; re-run `fmv3d features`)");
  FeatureSet f;
  f.width = r.Get<int32_t>("width");
  f.height = r.Get<int32_t>("height");
  if (f.width <= 0 || f.height <= 0)
    throw Error(path.string() + ": corrupt file (image size " + std::to_string(f.width) + "x" +
                std::to_string(f.height) + ")");
  const uint32_t n = r.Get<uint32_t>("keypoint count");
  const uint32_t name_len = r.Get<uint32_t>("name length");
  r.CheckFits(name_len, 1, "name bytes");
  f.image_name.resize(name_len);
  r.Bytes(f.image_name.data(), name_len, "image name");
  if (version >= 2) {
    f.contrast_threshold = r.Get<double>("contrast threshold");
    if (!(f.contrast_threshold >= 0 && f.contrast_threshold < 1))
      throw Error(path.string() + ": corrupt file (contrast threshold " + std::to_string(f.contrast_threshold) + ")");
  }
  r.CheckFits(n, 16 + 128 + 3, "keypoints");
  f.keypoints.resize(n);
  for (auto& k : f.keypoints) {
    k.x = r.Get<float>("keypoint");
    k.y = r.Get<float>("keypoint");
    k.scale = r.Get<float>("keypoint");
    k.orientation = r.Get<float>("keypoint");
  }
  if (descriptors) {
    f.descriptors.resize(n, 128);
    if (n > 0) r.Bytes(f.descriptors.data(), size_t{n} * 128, "descriptors");
  } else {
    r.Skip(size_t{n} * 128, "descriptors");
  }
  f.colors.resize(n);
  for (auto& c : f.colors) r.Bytes(c.data(), 3, "colours");
  r.End(kFeatEnd);
  return f;
}

void WriteMatches(const std::vector<VerifiedPair>& pairs, const fs::path& path) {
  Writer w;
  w.Bytes(kMatMagic, 8);
  w.Put<uint32_t>(kMatchFileVersion);
  w.Put<uint32_t>(static_cast<uint32_t>(pairs.size()));
  for (const auto& p : pairs) PutPair(&w, p);
  w.Bytes(kMatEnd, 8);
  w.Save(path);
}

std::vector<VerifiedPair> ReadMatches(const fs::path& path) {
  Reader r(path);
  std::vector<VerifiedPair> pairs(GetMatchHeader(&r, path));
  for (auto& p : pairs) p = GetPair(&r, path, /*inliers=*/true);
  r.End(kMatEnd);
  return pairs;
}

MatchFileWriter::MatchFileWriter(fs::path path)
    : path_(std::move(path)),
      // Named as core::WriteAtomically's temporaries, so a run killed mid-stream leaves nothing that the next run's
      // RemoveStaleTemporaries does not clear.
      part_(path_.parent_path() /
            ("." + path_.stem().string() + ".tmp" + std::to_string(getpid()) + ".part" + path_.extension().string())),
      out_(part_, std::ios::binary) {
  if (!out_) throw Error(path_.string() + ": cannot write");
  Writer w;
  w.Bytes(kMatMagic, 8);
  w.Put<uint32_t>(kMatchFileVersion);
  w.Put<uint32_t>(0);  // the pair count, set by Finish
  Flush(w.buf_);
}

MatchFileWriter::~MatchFileWriter() {
  if (finished_) return;
  out_.close();
  std::error_code ec;
  fs::remove(part_, ec);
}

void MatchFileWriter::Add(const VerifiedPair& pair) {
  Writer w;
  PutPair(&w, pair);
  Flush(w.buf_);
  ++count_;
}

void MatchFileWriter::Finish() {
  Writer w;
  w.Bytes(kMatEnd, 8);
  Flush(w.buf_);
  const auto count = static_cast<uint32_t>(count_);
  out_.seekp(12);
  out_.write(reinterpret_cast<const char*>(&count), sizeof count);
  out_.close();
  if (!out_) throw Error(path_.string() + ": cannot write");
  core::WriteAtomically(path_, [&](const fs::path& tmp) { fs::rename(part_, tmp); });
  finished_ = true;
}

void MatchFileWriter::Flush(const std::vector<char>& bytes) {
  out_.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  if (!out_) throw Error(path_.string() + ": cannot write");
}

struct MatchFileReader::Impl {
  explicit Impl(const fs::path& p) : path(p), in(p) {}
  fs::path path;
  StreamReader in;
};

MatchFileReader::MatchFileReader(const fs::path& path) : impl_(std::make_unique<Impl>(path)) {
  const uint32_t num_pairs = GetMatchHeader(&impl_->in, path);
  offsets_.reserve(num_pairs);
  ids_.reserve(num_pairs);
  for (uint32_t k = 0; k < num_pairs; ++k) {
    offsets_.push_back(impl_->in.position());
    const VerifiedPair p = GetPair(&impl_->in, path, /*inliers=*/false);
    ids_.emplace_back(p.image_id1, p.image_id2);
  }
  impl_->in.End(kMatEnd);
}

MatchFileReader::~MatchFileReader() = default;

VerifiedPair MatchFileReader::Read(size_t k) {
  impl_->in.Seek(offsets_.at(k));
  return GetPair(&impl_->in, impl_->path, /*inliers=*/true);
}

fs::path FeaturePath(const fs::path& features_dir, const std::string& frame_name) {
  return features_dir / (fs::path(frame_name).stem().string() + ".feat");
}
fs::path MatchesPath(const fs::path& matches_dir) { return matches_dir / "matches.bin"; }
fs::path MatchesSummaryPath(const fs::path& matches_dir) { return matches_dir / "matches.json"; }

void ValidateMatches(const std::vector<VerifiedPair>& pairs, const std::vector<size_t>& num_keypoints,
                     const std::string& what) {
  for (const auto& p : pairs) {
    if (p.image_id2 > num_keypoints.size())
      throw Error(what + ": pair " + std::to_string(p.image_id1) + "-" + std::to_string(p.image_id2) +
                  " refers to an image beyond the " + std::to_string(num_keypoints.size()) +
                  " frames (matches from another workspace? re-run `fmv3d match`)");
    const size_t n1 = num_keypoints[p.image_id1 - 1], n2 = num_keypoints[p.image_id2 - 1];
    for (const auto& m : p.inliers)
      if (m.idx1 >= n1 || m.idx2 >= n2)
        throw Error(what + ": pair " + std::to_string(p.image_id1) + "-" + std::to_string(p.image_id2) +
                    " refers to a keypoint beyond the feature files (stale matches? re-run `fmv3d match`)");
  }
}

}  // namespace fmv3d::features
