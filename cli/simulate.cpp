// imucal simulate: a motion program run by the physics simulator with a truth IMU (and a chamber
// profile driving the temperatures) into a run database.
#include "cli/commands.hpp"

#include <cstdio>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/imu_model.hpp"
#include "core/table_json.hpp"
#include "core/units.hpp"
#include "motion_programs/chamber.hpp"
#include "motion_programs/program.hpp"
#include "sim/simulator.hpp"
#include "sim/thermal_model.hpp"
#include "storage/run_db.hpp"
#include "cli/progress.hpp"

namespace imucal::cli {

namespace {

// The chamber profile, its coverage predicted before anything runs, and the thermal model.
std::unique_ptr<sim::ThermalModel> make_thermal(const SimulateArgs& a, const ImuModel& truth, double duration_s,
                                                std::string& record_json) {
  const motion::ChamberProfile profile = motion::load_chamber_profile(a.chamber);
  const auto problems = motion::validate_chamber_profile(profile, motion::ChamberLimits{});
  if (!problems.empty()) {
    std::string msg = "chamber profile '" + profile.name + "' exceeds the chamber:";
    for (const auto& p : problems) msg += "\n  - " + p;
    throw std::invalid_argument(msg);
  }
  sim::ThermalConfig tc;
  tc.stabilisation.enabled = a.stabilise;
  if (a.chamber_reach_C.size() == 2) {
    tc.chamber_min_C = a.chamber_reach_C[0];
    tc.chamber_max_C = a.chamber_reach_C[1];
  }
  for (const std::string& f : a.temp_faults) {
    sim::SensorFault fault;
    std::vector<std::string> part;
    std::stringstream ss(f);
    for (std::string x; std::getline(ss, x, ':');) part.push_back(x);
    if (part.size() < 3 || part.size() > 5)
      throw std::invalid_argument("--temp-fault '" + f + "': expected channel:kind:t0_s[:t1_s[:jump_C]]");
    fault.channel = part[0];
    fault.kind = part[1];
    fault.t0_s = std::stod(part[2]);
    if (part.size() > 3) fault.t1_s = std::stod(part[3]);
    if (part.size() > 4) fault.jump_C = std::stod(part[4]);
    tc.faults.push_back(fault);
  }
  const motion::CoverageMap cov = motion::predict_coverage(profile, tc.lags);
  std::printf("chamber profile '%s': %.1f h; predicted sensor coverage T %.2f..%.2f C, dT/dt %+.3f..%+.3f C/min, "
              "T bins heated %.0f %%, cooled %.0f %%, at rest %.0f %%\n%s",
              profile.name.c_str(), profile.duration_s() / 3600.0, cov.T_min_C, cov.T_max_C, cov.rate_min_C_per_min,
              cov.rate_max_C_per_min, 100 * cov.heating_T_fraction(), 100 * cov.cooling_T_fraction(),
              100 * cov.rest_T_fraction(), cov.ascii().c_str());
  record_json = nlohmann::json{{"profile", nlohmann::json::parse(profile.source_json)},
                               {"predicted_coverage", nlohmann::json::parse(cov.to_json())},
                               {"stabilisation", a.stabilise},
                               {"faults", a.temp_faults}}
                    .dump();
  return std::make_unique<sim::ThermalModel>(profile, truth, tc, duration_s);
}

}  // namespace

int run_simulate(const SimulateArgs& a) {
  const motion::TableLimits limits;
  const motion::Program program = motion::load_program(a.program, limits);
  const auto problems = motion::validate_program(program, limits);
  if (!problems.empty()) {
    std::cerr << "imucal simulate: program '" << program.name << "' violates the table limits:\n";
    for (const auto& p : problems) std::cerr << "  - " << p << "\n";
    return 2;
  }
  const ImuModel truth = a.imu == "ideal" ? ImuModel{} : read_imu_model_file(a.imu);
  sim::SimConfig cfg;
  cfg.rate_hz = a.rate_hz;
  cfg.seed = a.seed;
  cfg.duration_s = a.duration_s;
  cfg.site.middle_axis_azimuth_deg = a.azimuth_deg;
  cfg.mount.r0_p_m = Eigen::Vector3d(a.r0_mm[0], a.r0_mm[1], a.r0_mm[2]) * units::kMmToM;
  if (!a.table.empty()) cfg.table = table::read_table_certificate_file(a.table);
  std::string chamber_json;
  const std::unique_ptr<sim::ThermalModel> thermal =
      a.chamber.empty() ? nullptr
                        : make_thermal(a, truth, a.duration_s > 0 ? a.duration_s : program.duration_s(), chamber_json);
  cfg.thermal = thermal.get();
  sim::Simulator sim(program, truth, cfg);
  auto db = storage::RunDb::create(a.db, sim.meta());
  if (thermal) db.set_extra("chamber", chamber_json);
  const auto t0 = Clock::now();
  std::vector<ImuFrame> batch;
  batch.reserve(8192);
  Progress progress("simulate " + program.name, sim.frame_count());
  ImuFrame f;
  std::int64_t n = 0;
  while (sim.next(f)) {
    batch.push_back(f);
    if (batch.size() == batch.capacity()) {
      db.append(batch);
      db.append_temps(sim.take_temps());
      batch.clear();
      progress.update(n);
    }
    ++n;
  }
  db.append(batch);
  db.append_temps(sim.take_temps());
  db.flush();
  progress.done();
  const double wall = seconds_since(t0);
  std::printf("simulated '%s': %lld frames, %.1f s of data at %.0f Hz, in %.2f s (%.0f frames/s) -> %s\n",
              program.name.c_str(), static_cast<long long>(n), static_cast<double>(n) / a.rate_hz, a.rate_hz, wall,
              static_cast<double>(n) / wall, a.db.c_str());
  return 0;
}

}  // namespace imucal::cli
