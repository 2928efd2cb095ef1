// Times FK, a frame Jacobian, CRBA, RNEA and ABA of the Panda with
// Pinocchio's C++ templates (headers from the PyPI wheels), with the protocol
// of bench-anchors/README.md: a pool of 256 states, batches of 1000 calls,
// the median per call over 300 batches.
#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/parsers/urdf.hpp>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <vector>

namespace pin = pinocchio;

template <typename F> static double median_ns(F f) {
  for (int i = 0; i < 20000; ++i) f();
  std::vector<double> per_call;
  for (int b = 0; b < 300; ++b) {
    auto t = std::chrono::steady_clock::now();
    for (int i = 0; i < 1000; ++i) f();
    auto dt = std::chrono::steady_clock::now() - t;
    per_call.push_back(std::chrono::duration<double, std::nano>(dt).count() / 1000.0);
  }
  std::sort(per_call.begin(), per_call.end());
  return per_call[per_call.size() / 2];
}

int main(int argc, char **argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: pinocchio-anchor PANDA_URDF\n");
    return 2;
  }
  pin::Model model;
  pin::urdf::buildModel(argv[1], model);
  pin::Data data(model);
  const auto tip = model.getFrameId("peg_tip");
  uint64_t s = 7;
  auto next = [&s]() {
    s += 0x9E3779B97F4A7C15ull;
    uint64_t z = s;
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return double((z ^ (z >> 31)) >> 11) / double(1ull << 53);
  };
  const int n = model.nv;
  std::vector<Eigen::VectorXd> qs, vs, as;
  for (int k = 0; k < 256; ++k) {
    Eigen::VectorXd q(n), v(n), a(n);
    for (int i = 0; i < n; ++i) {
      const double lo = model.lowerPositionLimit[i], hi = model.upperPositionLimit[i];
      q[i] = lo + (hi - lo) * next();
    }
    for (int i = 0; i < n; ++i) v[i] = 2.0 * next() - 1.0;
    for (int i = 0; i < n; ++i) a[i] = 2.0 * next() - 1.0;
    qs.push_back(q); vs.push_back(v); as.push_back(a);
  }
  pin::Data::Matrix6x J(6, n);
  J.setZero();
  int k = 0;
  auto idx = [&k]() { k = (k + 1) % 256; return k; };
  const double fk = median_ns([&] { pin::forwardKinematics(model, data, qs[idx()]); });
  const double jac = median_ns([&] {
    pin::computeFrameJacobian(model, data, qs[idx()], tip, pin::LOCAL_WORLD_ALIGNED, J);
  });
  const double crba = median_ns([&] { pin::crba(model, data, qs[idx()]); });
  const double rnea = median_ns([&] { int i = idx(); pin::rnea(model, data, qs[i], vs[i], as[i]); });
  const double aba = median_ns([&] { int i = idx(); pin::aba(model, data, qs[i], vs[i], as[i]); });
  std::printf("pinocchio (median ns/call): fk %.0f  fk+jacobian %.0f  crba %.0f  rnea %.0f  forward_dynamics(aba) %.0f\n",
              fk, jac, crba, rnea, aba);
  return 0;
}
