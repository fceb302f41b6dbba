// Deterministic procedural noise for scene textures and terrain: hash-based value noise, fractal sums and
// cellular (Voronoi) noise. Pure functions of (coordinates, seed), so a scene is the same on every run and
// machine, and textures can be generated in parallel.
#pragma once

#include <cstdint>

namespace fmv3d::synth {

uint64_t Hash64(uint64_t x);
// Uniform in [0, 1) from integer lattice coordinates and a seed.
double LatticeRandom(int64_t x, int64_t y, uint64_t seed);
// Smooth value noise in [0, 1] (quintic interpolation of lattice values; lattice spacing 1).
double ValueNoise(double x, double y, uint64_t seed);
// Fractal sum of `octaves` value-noise layers (frequency ×2, amplitude ×gain each), normalised to [0, 1].
double Fbm(double x, double y, uint64_t seed, int octaves, double gain = 0.5);
// Ridged fractal noise in [0, 1] (sharp crests), for ridges and rock.
double RidgedFbm(double x, double y, uint64_t seed, int octaves);

// Cellular noise: the nearest of one jittered feature point per unit cell.
struct Cell {
  int64_t cx = 0, cy = 0;  // cell of the nearest feature point (a stable id for the region)
  double d1 = 0, d2 = 0;   // distances to the nearest and second-nearest points
};
Cell Voronoi(double x, double y, uint64_t seed);

}  // namespace fmv3d::synth
