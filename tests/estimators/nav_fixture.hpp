// Simulate a program in memory and navigate it: the textbook signatures and the accuracy floor.
#pragma once

#include <cmath>
#include <vector>

#include <Eigen/Dense>

#include "core/earth.hpp"
#include "core/units.hpp"
#include "sim/simulator.hpp"
#include "estimators/navigation_run.hpp"

namespace imucal::navtest {

struct NavResult {
  nav::NavSummary summary;
  std::vector<nav::NavErrorSample> samples;  // every output_interval_s
};

inline NavResult simulate_and_navigate(const motion::Program& program, const ImuModel& truth, const ImuModel& model,
                                       sim::SimConfig cfg, double output_interval_s = 1.0) {
  sim::Simulator s(program, truth, cfg);
  NavResult r;
  nav::NavigationRun run(s.meta(), model, output_interval_s, [&](const nav::NavErrorSample& e) { r.samples.push_back(e); });
  ImuFrame f;
  while (s.next(f)) run.push(f);
  r.summary = run.finish();
  return r;
}

// Schuler amplitude as method.md defines it: fit c0 + c1 cos(nu t) + c2 sin(nu t), sqrt(c1^2 + c2^2).
inline double schuler_amplitude(const std::vector<double>& t_s, const std::vector<double>& y, double t0_s,
                                double g_mps2) {
  const double nu = std::sqrt(g_mps2 / earth::kA_m);
  Eigen::MatrixXd A(static_cast<Eigen::Index>(t_s.size()), 3);
  Eigen::VectorXd b(static_cast<Eigen::Index>(t_s.size()));
  for (std::size_t i = 0; i < t_s.size(); ++i) {
    const auto r = static_cast<Eigen::Index>(i);
    A(r, 0) = 1;
    A(r, 1) = std::cos(nu * (t_s[i] - t0_s));
    A(r, 2) = std::sin(nu * (t_s[i] - t0_s));
    b(r) = y[i];
  }
  const Eigen::Vector3d c = A.colPivHouseholderQr().solve(b);
  return std::hypot(c[1], c[2]);
}

}  // namespace imucal::navtest
