// The test report of a run (imucal-test-report/1, docs/api.md "Test report"): what IEEE Std 952
// and 1293 ask a report to state, from what the run already holds: per test its figures with
// their standard uncertainty, its conditions (rates, positions, power-ons, durations), the run's
// conditions (site and its gravity, temperatures over the recording, rate, duration) and the
// verdict against the unit's part-number limits where there are limits. Pure: JSON in, JSON out.
#pragma once

#include <vector>

#include <nlohmann/json.hpp>

#include "core/recording.hpp"

namespace imucal::daemon {

// Minimum, mean and maximum of the chamber's and the IMU's temperatures over a recording.
struct TemperatureSummary {
  int samples = 0;
  double chamber_min_C = 0, chamber_mean_C = 0, chamber_max_C = 0;
  double imu_min_C = 0, imu_mean_C = 0, imu_max_C = 0;  // the mean of the six sensor temperatures
};
TemperatureSummary summarize_temperatures(const std::vector<TempSample>& temps);

// detail: the campaign as GET /api/campaigns/{id} gives it (results, verdict, spec); bench: what
// the certificate states about the bench (certificate_bench_json: gravity, simulated).
nlohmann::json test_report_json(const nlohmann::json& detail, const nlohmann::json& bench,
                                const TemperatureSummary& temperatures);

}  // namespace imucal::daemon
