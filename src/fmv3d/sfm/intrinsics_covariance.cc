#include "fmv3d/sfm/intrinsics_covariance.h"

#include <ceres/cost_function.h>
#include <ceres/manifold.h>
#include <ceres/problem.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/SparseCholesky>
#include <cstdint>
#include <unordered_map>
#include <utility>

namespace fmv3d::sfm {
namespace {

using RowMajorMap = Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>;
// The normal equations square the Jacobian's condition, and the Schur complements cancel most of each camera's
// information against the points': in double, an exact degeneracy (the focal against the depth of nadir images
// from one height) still left a pivot of 2e-12, while a real telephoto principal point keeps 1e-9. Accumulating
// and solving in extended precision (x87, 64-bit mantissa) leaves round-off near 1e-15 and a clear gap.
using Real = long double;
using MatX = Eigen::Matrix<Real, Eigen::Dynamic, Eigen::Dynamic>;
using VecX = Eigen::Matrix<Real, Eigen::Dynamic, 1>;

// Pivots of the LDLᵀ factorisations of the Jacobi-scaled system (unit diagonal) are each parameter's information
// left once the parameters before it are known, as a fraction of its own: 1 / pivot is its variance inflation.
// An exact degeneracy leaves round-off (≈ 1e-15 in extended precision); a weakly determined parameter still keeps
// far more (a telephoto's principal point against the rotations: 1e-9). Below this, the system is rank-deficient.
constexpr double kMinPivot = 1e-13;
// A point's eigenvalue below this fraction of its largest is an undetermined direction (round-off of a zero).
constexpr double kPointEigenFloor = 1e-12;

struct BlockInfo {
  enum Kind { kConstant, kPoint, kCamera } kind = kConstant;
  int index = -1;  // among the free points, or among the camera-side blocks
  int size = 0;    // tangent size
};

struct Layout {
  std::unordered_map<const double*, BlockInfo> blocks;
  std::vector<int> camera_sizes;  // camera-side blocks: the targets first, then the nuisance blocks
  int num_targets = 0, num_points = 0;
};

std::optional<Layout> Classify(const ceres::Problem& problem, const std::vector<const double*>& eliminated,
                               const std::vector<const double*>& targets) {
  Layout l;
  std::vector<double*> all;
  problem.GetParameterBlocks(&all);
  for (double* b : all)
    if (!problem.IsParameterBlockConstant(b)) l.blocks[b].size = problem.ParameterBlockTangentSize(b);
  auto claim = [&](const double* b, BlockInfo::Kind kind, int index) {
    auto it = l.blocks.find(b);
    if (it == l.blocks.end() || it->second.kind != BlockInfo::kConstant) return false;
    it->second.kind = kind;
    it->second.index = index;
    return true;
  };
  for (const double* t : targets) {
    if (!claim(t, BlockInfo::kCamera, l.num_targets++)) return std::nullopt;  // constant, unknown or repeated
    l.camera_sizes.push_back(l.blocks.at(t).size);
  }
  for (const double* p : eliminated)
    if (claim(p, BlockInfo::kPoint, l.num_points)) ++l.num_points;
  for (double* b : all)
    if (claim(b, BlockInfo::kCamera, static_cast<int>(l.camera_sizes.size())))
      l.camera_sizes.push_back(l.blocks.at(b).size);
  // Every block the claims above skipped is constant: mark those explicitly for the residual pass.
  for (double* b : all)
    if (!l.blocks.count(b)) l.blocks[b] = BlockInfo{};
  return l;
}

// The residual blocks grouped by their eliminated point: those of point p are order[start[p] .. start[p + 1]),
// those without one follow from start[num_points].
struct Groups {
  std::vector<ceres::ResidualBlockId> ids;
  std::vector<uint32_t> start, order;
};

std::optional<Groups> GroupByPoint(const ceres::Problem& problem, const Layout& layout) {
  Groups g;
  problem.GetResidualBlocks(&g.ids);
  std::vector<int> point_of(g.ids.size(), layout.num_points);
  std::vector<double*> params;
  g.start.assign(layout.num_points + 2, 0);
  for (size_t r = 0; r < g.ids.size(); ++r) {
    problem.GetParameterBlocksForResidualBlock(g.ids[r], &params);
    for (double* p : params) {
      const BlockInfo& info = layout.blocks.at(p);
      if (info.kind != BlockInfo::kPoint) continue;
      if (point_of[r] != layout.num_points) return std::nullopt;  // two eliminated blocks: not a point's residual
      point_of[r] = info.index;
    }
    ++g.start[point_of[r] + 1];
  }
  for (size_t k = 1; k < g.start.size(); ++k) g.start[k] += g.start[k - 1];
  g.order.resize(g.ids.size());
  std::vector<uint32_t> fill(g.start.begin(), g.start.end() - 1);
  for (size_t r = 0; r < g.ids.size(); ++r) g.order[fill[point_of[r]]++] = static_cast<uint32_t>(r);
  return g;
}

// The reduced camera system S in blocks S(a, b), a ≤ b, over the camera-side blocks; diagonal blocks are full.
class ReducedSystem {
 public:
  explicit ReducedSystem(const std::vector<int>& sizes) : sizes_(sizes) {}

  // S(a, b) += sign · Aᵀ B (its transpose into S(b, a) when a > b).
  template <typename MA, typename MB>
  void AddProduct(int a, const MA& A, int b, const MB& B, double sign) {
    if (a <= b)
      Block(a, b).noalias() += sign * A.transpose() * B;
    else
      Block(b, a).noalias() += sign * B.transpose() * A;
  }
  const std::unordered_map<uint64_t, MatX>& blocks() const { return blocks_; }
  std::pair<int, int> Pair(uint64_t key) const {
    return {static_cast<int>(key / sizes_.size()), static_cast<int>(key % sizes_.size())};
  }

 private:
  MatX& Block(int a, int b) {
    auto [it, added] = blocks_.try_emplace(static_cast<uint64_t>(a) * sizes_.size() + b);
    if (added) it->second.setZero(sizes_[a], sizes_[b]);
    return it->second;
  }
  const std::vector<int>& sizes_;
  std::unordered_map<uint64_t, MatX> blocks_;
};

// Evaluates residual blocks (corrected Jacobians in tangent space) and accumulates them into S, eliminating each
// group's point as the group ends.
class Eliminator {
 public:
  Eliminator(const ceres::Problem& problem, const Layout& layout, ReducedSystem* S)
      : problem_(problem), layout_(layout), S_(S), slot_(layout.camera_sizes.size(), -1) {}

  // One group: the residuals of one point (with_point) or residuals without one. False when an evaluation fails.
  bool AddGroup(const Groups& g, uint32_t begin, uint32_t end, bool with_point) {
    hpp_.resize(0, 0);
    for (uint32_t k = begin; k < end; ++k)
      if (!AddResidual(g.ids[g.order[k]])) return false;
    if (with_point && hpp_.size() > 0) EliminatePoint();
    for (int c : touched_) slot_[c] = -1;
    touched_.clear();
    return true;
  }

 private:
  bool AddResidual(ceres::ResidualBlockId id) {
    problem_.GetParameterBlocksForResidualBlock(id, &params_);
    const int rows = problem_.GetCostFunctionForResidualBlock(id)->num_residuals();
    const size_t n = params_.size();
    residual_.resize(rows);
    info_.resize(n);
    jac_.resize(n);
    jr_.resize(n);
    jac_ptr_.assign(n, nullptr);
    int point = -1;
    for (size_t i = 0; i < n; ++i) {
      info_[i] = &layout_.blocks.at(params_[i]);
      if (info_[i]->kind == BlockInfo::kConstant) continue;
      if (info_[i]->kind == BlockInfo::kPoint) point = static_cast<int>(i);
      jac_[i].resize(static_cast<size_t>(rows) * info_[i]->size);
      jac_ptr_[i] = jac_[i].data();
    }
    double cost = 0;
    if (!problem_.EvaluateResidualBlock(id, true, &cost, residual_.data(), jac_ptr_.data())) return false;
    for (size_t i = 0; i < n; ++i)
      if (jac_ptr_[i]) jr_[i] = RowMajorMap(jac_ptr_[i], rows, info_[i]->size).cast<Real>();
    for (size_t i = 0; i < n; ++i) {
      if (info_[i]->kind != BlockInfo::kCamera) continue;
      for (size_t j = i; j < n; ++j)
        if (info_[j]->kind == BlockInfo::kCamera) S_->AddProduct(info_[i]->index, jr_[i], info_[j]->index, jr_[j], 1);
    }
    if (point < 0) return true;
    const MatX& Jp = jr_[point];
    if (hpp_.size() == 0) hpp_.setZero(Jp.cols(), Jp.cols());
    hpp_.noalias() += Jp.transpose() * Jp;
    for (size_t i = 0; i < n; ++i) {
      const BlockInfo& a = *info_[i];
      if (a.kind != BlockInfo::kCamera) continue;
      if (slot_[a.index] < 0) {
        slot_[a.index] = static_cast<int>(touched_.size());
        touched_.push_back(a.index);
        if (w_.size() < touched_.size()) w_.resize(touched_.size());
        w_[slot_[a.index]].setZero(Jp.cols(), a.size);
      }
      w_[slot_[a.index]].noalias() += Jp.transpose() * jr_[i];
    }
    return true;
  }

  // S −= Hcp Hpp⁺ Hpc over the camera blocks the point touches. The pseudo-inverse drops the point's undetermined
  // directions, which its Hpc (in the range of Jpᵀ) does not reach.
  void EliminatePoint() {
    Eigen::SelfAdjointEigenSolver<MatX> eig(hpp_);
    const VecX& lambda = eig.eigenvalues();
    if (!(lambda.maxCoeff() > 0)) return;  // the point carries no information about anything
    VecX inv = VecX::Zero(lambda.size());
    for (int k = 0; k < lambda.size(); ++k)
      if (lambda[k] > kPointEigenFloor * lambda.maxCoeff()) inv[k] = 1 / lambda[k];
    const MatX pinv = eig.eigenvectors() * inv.asDiagonal() * eig.eigenvectors().transpose();
    g_.resize(touched_.size());
    for (size_t j = 0; j < touched_.size(); ++j) g_[j].noalias() = pinv * w_[j];
    for (size_t i = 0; i < touched_.size(); ++i)
      for (size_t j = i; j < touched_.size(); ++j) S_->AddProduct(touched_[i], w_[i], touched_[j], g_[j], -1);
  }

  const ceres::Problem& problem_;
  const Layout& layout_;
  ReducedSystem* S_;
  std::vector<double*> params_;
  std::vector<const BlockInfo*> info_;
  std::vector<double> residual_;
  std::vector<std::vector<double>> jac_;
  std::vector<double*> jac_ptr_;
  std::vector<MatX> jr_;  // the Jacobians in extended precision
  MatX hpp_;
  std::vector<int> slot_, touched_;  // camera block → its index in touched_ (−1: not touched by this point)
  std::vector<MatX> w_, g_;          // per touched block: Hpc and Hpp⁺ Hpc
};

// Σ_tt = (S_tt − S_tn S_nn⁻¹ S_nt)⁻¹ over the targets' tangent coordinates, Jacobi-scaled for the pivot tests.
std::optional<Eigen::MatrixXd> SolveTargets(const ReducedSystem& S, const Layout& layout) {
  const auto& sizes = layout.camera_sizes;
  std::vector<int> offset(sizes.size());
  int k = 0, n = 0;  // target and nuisance dimensions
  for (size_t c = 0; c < sizes.size(); ++c) {
    const bool target = static_cast<int>(c) < layout.num_targets;
    offset[c] = target ? k : n;
    (target ? k : n) += sizes[c];
  }
  auto global = [&](int c, int r) {
    return static_cast<int>(c) < layout.num_targets ? offset[c] + r : k + offset[c] + r;
  };
  VecX scale = VecX::Zero(k + n);  // 1 / sqrt(diag S), targets first
  for (const auto& [key, m] : S.blocks()) {
    const auto [a, b] = S.Pair(key);
    if (a == b)
      for (int r = 0; r < sizes[a]; ++r) scale[global(a, r)] = m(r, r);
  }
  if (!(scale.minCoeff() > 0)) return std::nullopt;  // a free parameter no residual informs
  scale = scale.cwiseSqrt().cwiseInverse();
  MatX C = MatX::Zero(k, k), B = MatX::Zero(n, k);
  std::vector<Eigen::Triplet<Real>> upper;
  for (const auto& [key, m] : S.blocks()) {
    const auto [a, b] = S.Pair(key);
    for (int r = 0; r < sizes[a]; ++r)
      for (int c = 0; c < sizes[b]; ++c) {
        const int i = global(a, r), j = global(b, c);
        const Real v = m(r, c) * scale[i] * scale[j];
        if (i < k && j < k)
          C(i, j) = C(j, i) = v;
        else if (i < k || j < k)
          B(std::max(i, j) - k, std::min(i, j)) = v;
        else if (a != b || r <= c)
          upper.emplace_back(std::min(i, j) - k, std::max(i, j) - k, v);
      }
  }
  if (n > 0) {
    Eigen::SparseMatrix<Real> A(n, n);
    A.setFromTriplets(upper.begin(), upper.end());
    upper = {};
    Eigen::SimplicialLDLT<Eigen::SparseMatrix<Real>, Eigen::Upper> ldlt(A);
    if (ldlt.info() != Eigen::Success || !(ldlt.vectorD().minCoeff() > kMinPivot)) return std::nullopt;
    const MatX X = ldlt.solve(B);
    C.noalias() -= B.transpose() * X;
  }
  const Eigen::LDLT<MatX> schur(C);
  if (schur.info() != Eigen::Success || !(schur.vectorD().minCoeff() > kMinPivot)) return std::nullopt;
  const MatX inv = schur.solve(MatX::Identity(k, k));
  return (scale.head(k).asDiagonal() * inv * scale.head(k).asDiagonal()).cast<double>();
}

}  // namespace

std::optional<std::vector<Eigen::MatrixXd>> MarginalCovariance(const ceres::Problem& problem,
                                                               const std::vector<const double*>& eliminated,
                                                               const std::vector<const double*>& targets) {
  if (targets.empty()) return std::nullopt;
  const auto layout = Classify(problem, eliminated, targets);
  if (!layout) return std::nullopt;
  const auto groups = GroupByPoint(problem, *layout);
  if (!groups) return std::nullopt;
  ReducedSystem S(layout->camera_sizes);
  {
    Eliminator elim(problem, *layout, &S);
    for (int p = 0; p <= layout->num_points; ++p)
      if (!elim.AddGroup(*groups, groups->start[p], groups->start[p + 1], p < layout->num_points)) return std::nullopt;
  }
  const auto cov = SolveTargets(S, *layout);
  if (!cov) return std::nullopt;
  // Lift each target's tangent block to its ambient coordinates: P Σ Pᵀ with P the manifold's plus-Jacobian.
  std::vector<Eigen::MatrixXd> out;
  int offset = 0;
  for (const double* t : targets) {
    const int ambient = problem.ParameterBlockSize(t), tangent = layout->blocks.at(t).size;
    Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> P =
        Eigen::MatrixXd::Identity(ambient, tangent);
    if (const ceres::Manifold* m = problem.GetManifold(t)) m->PlusJacobian(t, P.data());
    out.push_back(P * cov->block(offset, offset, tangent, tangent) * P.transpose());
    offset += tangent;
  }
  return out;
}

}  // namespace fmv3d::sfm
