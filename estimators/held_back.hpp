// Choosing a model's size by how well it predicts data it was not fitted to: the one rule for
// every estimator that picks polynomial degrees (stage 2's degrees in T and dT/dt, the rate-steps
// test's scale nonlinearity).
#pragma once

#include <cstddef>
#include <vector>

namespace imucal::held_back {

// One candidate model: its number of parameters and the squared error of every sample predicted by
// a fit that did not see it (weighted as the fit weighs it).
struct Score {
  int params = 0;
  std::vector<double> e2;
  double mean_e2() const;
};

struct Rule {
  // A simpler model is kept unless the best one predicts held-back samples better, in mean square,
  // by more than standard_errors standard errors of the paired difference, by more than
  // min_improvement of its own mean square, and by more than resolution^2: an improvement within
  // the scatter of the estimates, or too small to matter, never buys a parameter.
  double standard_errors = 2.0;
  double min_improvement = 0.0;
  double resolution = 0.0;
  // When not 0: a simpler model whose held-back mean square is more than this many times the best
  // one's is beaten whatever the paired test says (the floor above still applies). With few samples
  // and a misfit far above the noise the paired differences are all of one sign but unequal, and
  // their t stays small however large the misfit: a pure cubic over the six interior rates of the
  // short rate ladder gives 1.92 at most, noise-free. Between two models that both hold the data,
  // held-back mean squares differ by the noise's scatter, nowhere near such a ratio.
  double decisive_ratio = 0.0;
};

// The index of the chosen candidate: the one with the fewest parameters (among equals, the better
// predictor) that the best predictor does not beat under the rule. Candidates all score the same
// samples; throws std::invalid_argument when there are none.
std::size_t choose(const std::vector<Score>& candidates, const Rule& rule);

}  // namespace imucal::held_back
