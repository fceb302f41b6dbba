// Random test vectors drawn in a defined order (docs/architecture.md: never two draws in one call's arguments).
#pragma once

#include <Eigen/Core>

namespace fmv3d::test {

// A random vector drawn last component first, one draw per statement (two draws in one call's arguments have no
// defined order): the order in which some scenes were first drawn (GCC's argument order), so their figures stay.
template <int N, class Distribution, class Rng>
Eigen::Matrix<double, N, 1> DrawLastFirst(Distribution& d, Rng& rng) {
  Eigen::Matrix<double, N, 1> v;
  for (int i = N - 1; i >= 0; --i) v[i] = d(rng);
  return v;
}

}  // namespace fmv3d::test
