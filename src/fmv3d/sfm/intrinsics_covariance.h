// The posterior covariance of a few parameter blocks of a solved Ceres problem (bundle adjustment's intrinsics),
// from the normal equations of the reduced camera system rather than ceres::Covariance's sparse QR of the whole
// Jacobian: that took the sparse stage of a 100-frame 960x540 orbit to an 8 GiB peak (0.9 GiB without it) and
// minutes per call (bench/results/cov9.md).
//
// The information matrix H = JᵀJ is accumulated residual block by residual block (Jacobians in the tangent spaces
// of the parameter blocks, with the robust loss applied as Ceres' solver applies it), the eliminated blocks (3D
// points) are eliminated one at a time (S = Hcc − Σ Hcp Hpp⁺ Hpc), and the targets' marginal covariance is the
// inverse of the Schur complement of the other free blocks (poses) onto the targets:
//   Σ_tt = (S_tt − S_tn S_nn⁻¹ S_nt)⁻¹,
// with S_nn factorised by a sparse LDLᵀ (AMD ordering). Memory: S in blocks, one per pair of free blocks that share
// a point, ≈ 60 bytes per stored value of S_nn's upper triangle at the peak (the block, its triplet and the sparse
// matrix, in long double) plus the factor's fill (20 bytes per value). Video, images within a covisibility window
// of w: O(n·w), 2000 images with w = 50 ≈ 0.3 GB. At worst every image sees every other and S_nn is dense, 18n²
// values: 500 images ≈ 0.35 GB, 1000 ≈ 1.4 GB with the fill. Per residual the pass keeps only its id and group
// (16 bytes), never its Jacobian.
#pragma once

#include <Eigen/Core>
#include <optional>
#include <vector>

namespace ceres {
class Problem;
}

namespace fmv3d::sfm {

// The marginal covariance of each target block at the problem's current values, for unit residual variance (the
// caller scales by σ²): (JᵀJ)⁻¹ restricted to the block, in its ambient coordinates (lifted through its manifold's
// plus-Jacobian, so the rows and columns of coordinates a SubsetManifold holds are zero), as Ceres' Covariance with
// apply_loss_function returns it.
// eliminated: blocks eliminated first (3D points); a residual block may involve at most one free one. A point whose
// own 3×3 block is singular (too few or degenerate observations) is pseudo-inverted: its undetermined directions
// do not couple to any camera parameter (they are in the null space of its Jacobian), so the cameras' information
// is exactly what the point's determined directions leave.
// targets: free parameter blocks; every other free block is a nuisance parameter (poses).
// Returns nothing when the information matrix is singular in the non-eliminated parameters (a gauge freedom left,
// a target the data do not determine), when a target is constant or a residual involves two eliminated blocks.
std::optional<std::vector<Eigen::MatrixXd>> MarginalCovariance(const ceres::Problem& problem,
                                                               const std::vector<const double*>& eliminated,
                                                               const std::vector<const double*>& targets);

}  // namespace fmv3d::sfm
