// Native cost of the joint-torque regressor and of RNEA, one block of samples per call.
//
//   regressor_floor MODEL.txt N SEED
//
// Reads the model saved by pinocchio.Model.saveToText (the very model the Python
// side uses; the wheel ships no URDF parser headers), draws N states (q in the joint limits,
// dq, ddq standard normal), then times, in one native loop over the block:
//   pinocchio::computeJointTorqueRegressor  and  pinocchio::rnea
// and prints one JSON line: microseconds per sample for each, and a checksum
// (so the loops cannot be optimized away). Used by experiments/bench_floor.py.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <vector>

#include "pinocchio/algorithm/regressor.hpp"
#include "pinocchio/algorithm/rnea.hpp"
#include "pinocchio/multibody.hpp"
#include "pinocchio/serialization.hpp"

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: %s MODEL.txt N [SEED]\n", argv[0]);
    return 2;
  }
  pinocchio::Model model;
  model.loadFromText(argv[1]);
  pinocchio::Data data(model);
  const long n = std::atol(argv[2]);
  std::mt19937_64 gen(argc > 3 ? std::atol(argv[3]) : 0);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::vector<Eigen::VectorXd> q(n), v(n), a(n);
  for (long k = 0; k < n; ++k) {
    q[k] = pinocchio::neutral(model);
    for (int i = 0; i < model.nq; ++i) {
      double lo = model.lowerPositionLimit[i], hi = model.upperPositionLimit[i];
      if (std::isfinite(lo) && std::isfinite(hi) && hi > lo) q[k][i] = lo + (hi - lo) * unit(gen);
    }
    v[k].resize(model.nv);
    a[k].resize(model.nv);
    for (int i = 0; i < model.nv; ++i) {
      v[k][i] = normal(gen);
      a[k][i] = normal(gen);
    }
  }
  double checksum = 0.0;
  auto t0 = std::chrono::steady_clock::now();
  for (long k = 0; k < n; ++k) {
    const auto& Y = pinocchio::computeJointTorqueRegressor(model, data, q[k], v[k], a[k]);
    checksum += Y(0, 0);
  }
  auto t1 = std::chrono::steady_clock::now();
  for (long k = 0; k < n; ++k) {
    const auto& tau = pinocchio::rnea(model, data, q[k], v[k], a[k]);
    checksum += tau[0];
  }
  auto t2 = std::chrono::steady_clock::now();
  const double us_reg = std::chrono::duration<double, std::micro>(t1 - t0).count() / n;
  const double us_rnea = std::chrono::duration<double, std::micro>(t2 - t1).count() / n;
  std::printf("{\"n\": %ld, \"nv\": %d, \"regressor_us\": %.4f, \"rnea_us\": %.4f, \"checksum\": %.6g}\n",
              n, model.nv, us_reg, us_rnea, checksum);
  return 0;
}
