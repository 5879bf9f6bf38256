// Stage 2 acceptance (issue 5) on the simulated 12 h chamber run over 15..35 C: residuals after
// compensation, degree selection on clean and noisy data, the IMU's thermal stabilisation, and the
// time a whole 12 h run takes. Label slow (about a minute in Release).
#include <gtest/gtest.h>

#include "test_thermal_fixture.hpp"

using namespace imucal;

namespace {

// The truth's degree of every coefficient, from its thermal section.
std::map<std::string, std::pair<int, int>> truth_degrees(const ImuModel& truth) {
  const thermal::ThermalSection s = *thermal::thermal_of(truth);
  std::map<std::string, std::pair<int, int>> out;
  for (const auto& c : thermal::coefficients()) {
    const auto& p = s.poly[static_cast<std::size_t>(c.index)];
    out[thermal::full_key(c)] = {static_cast<int>(p.T.size()), static_cast<int>(p.dTdt.size())};
  }
  return out;
}

// The seed's figures after compensation (ch. 3), the acceptance.
const std::map<std::string, double> kAcceptance = {
    {"accel.bias_mps2", 1e-5},   {"accel.scale_ppm", 10.0},    {"accel.misalignment_arcsec", 3.0},
    {"gyro.bias_dph", 0.01},     {"gyro.scale_pos_ppm", 20.0}, {"gyro.scale_neg_ppm", 20.0},
    {"gyro.misalignment_arcsec", 2.0}};

}  // namespace

TEST(ThermalLong, TwelveHourRunMeetsTheSeedsFiguresAfterCompensation) {
  const ImuModel truth = thermaltest::truth_thermal();  // noise and the unmodelled oscillation
  const auto want = truth_degrees(truth);
  for (std::uint64_t seed : {3u, 4u, 5u}) {
    thermaltest::Run r;
    r.seed = seed;
    const auto o = thermaltest::run(truth, r);
    std::printf("seed %llu:\n", static_cast<unsigned long long>(seed));
    thermaltest::print(o);
    EXPECT_EQ(o.result.cycles_used, 83);
    EXPECT_LT(o.sim_and_cycles_s + o.fit_s, 300.0);
    for (const auto& [group, limit] : kAcceptance) {
      const double res = o.report.at("residual").at(group).get<double>();
      EXPECT_LE(res, limit) << group << " seed " << seed;
      EXPECT_GT(o.report.at("before").at(group).get<double>(), 3 * limit) << group;  // uncompensated it fails
    }
    // With noise the chosen degree never exceeds the truth's.
    for (const auto& [key, d] : o.report.at("degrees").items()) {
      EXPECT_LE(d.at("T_degree").get<int>(), want.at(key).first) << key << " seed " << seed;
      EXPECT_LE(d.at("dTdt_degree").get<int>(), want.at(key).second) << key << " seed " << seed;
    }
  }
}

TEST(ThermalLong, CleanDataGivesTheTruthsDegreeEverywhere) {
  const ImuModel truth = thermaltest::clean(thermaltest::truth_thermal());
  const auto want = truth_degrees(truth);
  const auto o = thermaltest::run(truth, thermaltest::Run{});
  thermaltest::print(o);
  for (const auto& [key, d] : o.report.at("degrees").items()) {
    EXPECT_EQ(d.at("T_degree").get<int>(), want.at(key).first) << key;
    EXPECT_EQ(d.at("dTdt_degree").get<int>(), want.at(key).second) << key;
  }
  for (const auto& [group, limit] : kAcceptance)
    EXPECT_LE(o.report.at("residual").at(group).get<double>(), 0.3 * limit) << group;
}

TEST(ThermalLong, WithThermalStabilisationTheFogBiasIsWithinAThousandthDegreePerHour) {
  // The seed's order: characterise over 15..35 C, then run with the IMU's stabilisation (a relay
  // heater holding the sensors near 55 C within about 0.4 C, docs/thermal.md); that run keeps the
  // shape of the models (their dT/dt part is what the control cycle excites) and fits their
  // constants at the stabilised temperature, 20 C beyond the characterised range.
  const ImuModel truth = thermaltest::truth_thermal();
  for (std::uint64_t seed : {11u, 13u, 15u}) {
    thermaltest::Run full;
    full.seed = seed;
    const auto characterised = thermaltest::run(truth, full);
    thermaltest::Run stab;
    stab.seed = seed + 1;
    stab.thermal.stabilisation.enabled = true;
    const auto o = thermaltest::run(truth, stab, &characterised.result.model, "constants");
    std::printf("seeds %llu/%llu: stabilised run, shape from 15..35 C, constants from this run:\n",
                static_cast<unsigned long long>(seed), static_cast<unsigned long long>(seed + 1));
    thermaltest::print(o);
    const double p2p = o.report.at("truth_peak_to_peak").at("gyro.bias_dph").get<double>();
    const double after = o.report.at("residual").at("gyro.bias_dph").get<double>();
    // Stabilisation alone is not enough (seed ch. 3): the FOG bias still moves with the control
    // cycle's dT/dt by more than 0.005 deg/h over the run.
    EXPECT_GT(p2p, 0.005) << "seed " << seed;
    EXPECT_LE(after, 0.001) << "seed " << seed;
    std::printf("FOG bias with stabilisation: truth peak to peak %.4f deg/h, compensated %.5f\n", p2p, after);
    if (seed != 11u) continue;
    // For the record: the 15..35 C models unchanged (extrapolated to 55 C), and a fit of the
    // stabilised run alone (its 0.4 C cannot separate T from noise, and the cycle's fast dT/dt
    // moves the bias inside each 8.6 min table cycle).
    const auto judged = thermaltest::run(truth, stab, &characterised.result.model, "judge");
    const auto alone = thermaltest::run(truth, stab);
    std::printf("  the same run judged with the 15..35 C models as they are: %.5f deg/h; fitted on its own: %.5f deg/h\n",
                judged.report.at("residual").at("gyro.bias_dph").get<double>(),
                alone.report.at("residual").at("gyro.bias_dph").get<double>());
  }
}

