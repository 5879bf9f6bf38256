#include "estimators/held_back.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>

namespace imucal::held_back {

double Score::mean_e2() const {
  return e2.empty() ? 0.0 : std::accumulate(e2.begin(), e2.end(), 0.0) / static_cast<double>(e2.size());
}

std::size_t choose(const std::vector<Score>& candidates, const Rule& rule) {
  if (candidates.empty()) throw std::invalid_argument("held_back::choose: no candidate models");
  std::size_t best = 0;
  for (std::size_t c = 1; c < candidates.size(); ++c)
    if (candidates[c].mean_e2() < candidates[best].mean_e2()) best = c;
  const double best_ms = candidates[best].mean_e2();
  const double floor = std::max(rule.min_improvement * best_ms, rule.resolution * rule.resolution);
  std::vector<std::size_t> order(candidates.size());
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    return candidates[a].params != candidates[b].params ? candidates[a].params < candidates[b].params
                                                        : candidates[a].mean_e2() < candidates[b].mean_e2();
  });
  const std::vector<double>& eb = candidates[best].e2;
  const auto n = static_cast<double>(eb.size());
  for (std::size_t c : order) {
    const std::vector<double>& e = candidates[c].e2;
    if (e.size() != eb.size()) throw std::invalid_argument("held_back::choose: candidates score different samples");
    double mean = 0, sq = 0;
    for (std::size_t i = 0; i < e.size(); ++i) {
      const double d = e[i] - eb[i];
      mean += d;
      sq += d * d;
    }
    if (n > 0) {
      mean /= n;
      sq /= n;
    }
    const double se = n > 0 ? std::sqrt(std::max(0.0, sq - mean * mean) / n) : 0.0;
    const bool decisive = rule.decisive_ratio > 0.0 && candidates[c].mean_e2() > rule.decisive_ratio * best_ms;
    if (!decisive && mean <= std::max(rule.standard_errors * se, floor)) return c;
    if (decisive && mean <= floor) return c;
  }
  return best;  // not reached: the best candidate always passes against itself
}

}  // namespace imucal::held_back
