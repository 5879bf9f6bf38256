// imucal: the command line. A thin shell over the libraries: simulate, navigate, export, import,
// campaign run.
#include <termios.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <limits>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "core/imu_model.hpp"
#include "core/units.hpp"
#include "daemon/service/campaign_runner.hpp"
#include "daemon/service/command_line.hpp"
#include "daemon/service/config.hpp"
#include "daemon/service/device_config.hpp"
#include "daemon/service/password_hash.hpp"
#include "daemon/service/service.hpp"
#include "sim/sim_devices.hpp"
#include "sim/simulator.hpp"
#include "sim/thermal_model.hpp"
#include "estimators/direct_calibration.hpp"
#include "estimators/lever_arm.hpp"
#include "estimators/evaluate.hpp"
#include "estimators/nav_filter.hpp"
#include "estimators/noise.hpp"
#include "estimators/navigation_run.hpp"
#include "estimators/thermal.hpp"
#include "motion_programs/chamber.hpp"
#include "motion_programs/program.hpp"
#include "pipeline/pipeline.hpp"
#include "plan/optimize.hpp"
#include "plan/plan.hpp"
#include "bench/storage_bench.hpp"
#include "storage/bundle.hpp"
#include "storage/run_db.hpp"

namespace {

using namespace imucal;
using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// Progress on stderr, at most every few percent, so long runs show they are alive.
class Progress {
 public:
  Progress(std::string what, std::int64_t total) : what_(std::move(what)), total_(total) {}
  void update(std::int64_t done) {
    if (total_ <= 0) return;
    const int pct = static_cast<int>(100 * done / total_);
    if (pct >= next_) {
      std::fprintf(stderr, "\r%s: %3d %%", what_.c_str(), pct);
      std::fflush(stderr);
      next_ = pct + 5;
    }
  }
  void done() { std::fprintf(stderr, "\r%s: 100 %%\n", what_.c_str()); }

 private:
  std::string what_;
  std::int64_t total_;
  int next_ = 0;
};

struct SimulateArgs {
  std::string program, imu = "ideal", db;
  double rate_hz = 1000, duration_s = 0, azimuth_deg = 0;
  std::uint64_t seed = 1;
  std::vector<double> r0_mm = {0, 0, 0};
  std::string chamber;                       // stage 2: a chamber profile drives the temperatures
  bool stabilise = false;
  std::vector<std::string> temp_faults;      // channel:kind:t0:t1[:jump_C]
  std::vector<double> chamber_reach_C;       // lo hi: what the chamber can reach (a fault)
};

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

int cmd_simulate(const SimulateArgs& a) {
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

struct NavigateArgs {
  std::string db, model, out, summary_json;
  double interval_s = 1.0;
};

int cmd_navigate(const NavigateArgs& a) {
  const auto db = storage::RunDb::open(a.db);
  const RecordingMeta meta = db.meta();
  const ImuModel model = a.model.empty() ? ImuModel{} : read_imu_model_file(a.model);
  std::ofstream csv(a.out);
  if (!csv) throw std::runtime_error(a.out + ": cannot write");
  csv << "t_s,dv_e_mps,dv_n_mps,dp_e_m,dp_n_m,att_e_arcsec,att_n_arcsec,att_u_arcsec\n";
  char line[256];
  nav::NavigationRun run(meta, model, a.interval_s, [&](const nav::NavErrorSample& e) {
    const Eigen::Vector3d att = e.attitude_err_n_rad * units::kRadToArcsec;
    std::snprintf(line, sizeof line, "%.3f,%.9e,%.9e,%.6e,%.6e,%.4f,%.4f,%.4f\n", e.t_s, e.dv_n_mps.x(),
                  e.dv_n_mps.y(), e.dp_n_m.x(), e.dp_n_m.y(), att.x(), att.y(), att.z());
    csv << line;
  });
  const auto t0 = Clock::now();
  Progress progress("navigate", db.frame_count());
  std::int64_t n = 0;
  // Temperatures in time order with the frames, for a model with a thermal section.
  const std::vector<TempSample> temps = db.temps();
  std::size_t next_temp = 0;
  db.for_each_frame([&](const ImuFrame& f) {
    while (next_temp < temps.size() && temps[next_temp].t_ns <= f.t_ns) run.push_temp(temps[next_temp++]);
    run.push(f);
    if ((++n & 0xFFFF) == 0) progress.update(n);
  });
  const nav::NavSummary s = run.finish();
  progress.done();
  const double wall = seconds_since(t0);
  nlohmann::json j = {{"duration_s", s.duration_s},
                      {"frames", s.frames},
                      {"max_velocity_error_mps", s.max_velocity_error_mps},
                      {"max_position_error_m", s.max_position_error_m},
                      {"max_attitude_error_arcsec", s.max_attitude_error_rad * units::kRadToArcsec},
                      {"model", a.model.empty() ? "ideal" : a.model},
                      {"wall_time_s", wall},
                      {"frames_per_s", static_cast<double>(n) / wall}};
  if (!a.summary_json.empty()) {
    std::ofstream out(a.summary_json);
    if (!out) throw std::runtime_error(a.summary_json + ": cannot write");
    out << j.dump(1) << "\n";
  }
  std::printf("navigated %.1f s: max horizontal velocity error %.3e m/s, position error %.3e m, attitude %.3f\" "
              "(%.0f frames/s)\n",
              s.duration_s, s.max_velocity_error_mps, s.max_position_error_m,
              s.max_attitude_error_rad * units::kRadToArcsec, static_cast<double>(n) / wall);
  return 0;
}

struct CalibrateArgs {
  std::string db, stage = "direct", model, out, frame = "instrument";
  int passes = 1;
  std::string report;                   // stage thermal: imucal-thermal-report/1
  int statics_per_cycle = 0;            // stage thermal: when the statics carry no cycle names
  double t_ref_C = std::numeric_limits<double>::quiet_NaN();
  std::vector<double> range_C = {15.0, 35.0};
  bool keep_shape = false;              // stage thermal: fit only the constants, keep the polynomials
};

// What each stage of the pipeline says, on stdout: its notes and its own figures.
void print_outcome(const pipeline::Outcome& o) {
  for (const auto& note : o.notes) std::printf("%s\n", note.c_str());
  if (o.thermal) {
    const thermal::Result& r = *o.thermal;
    const auto report = nlohmann::json::parse(r.report_json);
    std::printf("stage thermal: %d of %d cycles used, T_ref %.1f C; largest deviation over the run (%s):\n",
                r.cycles_used, r.cycles_total, report.at("T_ref_C").get<double>(),
                report.at("residual_source").get<std::string>().c_str());
    std::printf("  %-28s %14s %14s\n", "coefficient", "before", "compensated");
    for (const char* g : thermal::groups())
      std::printf("  %-28s %14.6g %14.6g\n", g, report.at("before").value(g, 0.0), report.at("residual").value(g, 0.0));
  }
  if (o.rate_steps) {
    static const char* const kAxes[3] = {"x", "y", "z"};
    for (const rate_steps::Axis& a : o.rate_steps->axes) {
      if (!a.tested) continue;
      std::printf("gyro %s: scale + %.3f +- %.3f ppm, - %.3f +- %.3f ppm, asymmetry %.3f +- %.3f ppm; IEEE 952 "
                  "nonlinearity %.3f +- %.3f ppm of %.0f deg/s (at %+.0f deg/s); nonlinear degree %d",
                  kAxes[a.axis], a.scale_pos_ppm, a.scale_pos_sigma_ppm, a.scale_neg_ppm, a.scale_neg_sigma_ppm,
                  a.asymmetry_ppm, a.asymmetry_sigma_ppm, a.nonlinearity_ppm_fs, a.nonlinearity_sigma_ppm_fs,
                  a.full_scale_dps, a.nonlinearity_at_dps, a.degree);
      for (int k = 0; k < a.degree; ++k)
        std::printf("%s c%d %.3f +- %.3f", k == 0 ? ":" : ",", k + 1, a.nonlinear_ppm[static_cast<std::size_t>(k)],
                    a.nonlinear_sigma_ppm[static_cast<std::size_t>(k)]);
      std::printf("\n  %10s %12s %9s %12s %10s\n", "rate deg/s", "scale ppm", "sigma", "model ppm", "resid ppm");
      for (const rate_steps::Step& st : a.steps)
        std::printf("  %+10.2f %12.3f %9.3f %12.3f %10.3f\n", st.rate_dps, st.scale_ppm, st.sigma_ppm,
                    a.scale_ppm_at(st.rate_dps), st.fit_residual_ppm);
    }
  }
  if (o.tumble) {
    // Every coefficient the tumble gives, with its sigma, in the units of the model file.
    const ImuModel& m = o.tumble->model;
    const ImuErrorSet& s = *m.sigma;
    static const char* const kAxes[3] = {"x", "y", "z"};
    constexpr double ug = 1e6 / units::kStandardGravity_mps2;
    std::printf("  %-6s %22s %18s %18s %18s %26s\n", "accel", "bias ug", "scale ppm", "K2 ug/g^2", "K3 ug/g^3", "residual rms ug");
    for (int j = 0; j < 3; ++j)
      std::printf("  %-6s %12.3f +- %6.3f %9.3f +- %5.3f %9.3f +- %5.3f %9.3f +- %5.3f %26.3f\n", kAxes[j], m.accel.bias_mps2[j] * ug,
                  s.accel.bias_mps2[j] * ug, m.accel.scale[j] * 1e6, s.accel.scale[j] * 1e6, m.accel.k2_per_g[j] * 1e6,
                  s.accel.k2_per_g[j] * 1e6, m.accel.k3_per_g2[j] * 1e6, s.accel.k3_per_g2[j] * 1e6,
                  o.tumble->accel_residual_rms_mps2[j] * ug);
    std::printf("  %-6s %22s   g-sensitivity deg/h/g along o x, y, z\n", "gyro", "bias deg/h");
    for (int j = 0; j < 3; ++j) {
      std::printf("  %-6s %12.5f +- %7.5f", kAxes[j], m.gyro.bias_radps[j] * units::kRadpsToDph, s.gyro.bias_radps[j] * units::kRadpsToDph);
      for (int k = 0; k < 3; ++k)
        std::printf(" %9.5f +- %7.5f", m.gyro.g_sensitivity_radps_per_g(j, k) * units::kRadpsToDph,
                    s.gyro.g_sensitivity_radps_per_g(j, k) * units::kRadpsToDph);
      std::printf("\n");
    }
  }
  if (o.warm_up) {
    // Each channel's transient from power-on, in deg/h and ug.
    std::printf("warm-up over %.0f s from power-on:\n  %-8s %24s %22s %22s %10s\n", o.warm_up->duration_s, "channel",
                "amplitude", "time constant s", "settle time s", "band");
    for (const warm_up::Channel& ch : o.warm_up->channels) {
      const double k = ch.gyro ? units::kRadpsToDph : 1e6 / units::kStandardGravity_mps2;
      const char* unit = ch.gyro ? "deg/h" : "ug";
      std::printf("  %-6s %c %11.5f +- %7.5f %-5s", ch.gyro ? "gyro" : "accel", "xyz"[ch.axis], ch.amplitude * k,
                  ch.amplitude_sigma * k, unit);
      if (ch.detected)
        std::printf(" %9.0f +- %7.0f %11.0f +- %7.0f %7.4g %s\n", ch.time_constant_s, ch.time_constant_sigma_s,
                    ch.settle_time_s, ch.settle_time_sigma_s, ch.band * k, unit);
      else
        std::printf(" no transient above the noise\n");
    }
  }
  if (o.repeatability) {
    const repeatability::Result& r = *o.repeatability;
    std::printf("turn-on to turn-on repeatability over %zu power-ons:\n  %-8s %24s %12s %12s\n", r.turn_ons.size(),
                "channel", "repeatability (1 sigma)", "spread", "noise");
    for (const repeatability::Channel& ch : r.channels) {
      const double k = ch.gyro ? units::kRadpsToDph : 1e6 / units::kStandardGravity_mps2;
      std::printf("  %-6s %c %11.5f +- %7.5f %-5s %12.5f %12.5f\n", ch.gyro ? "gyro" : "accel", "xyz"[ch.axis],
                  ch.repeatability * k, ch.repeatability_sigma * k, ch.gyro ? "deg/h" : "ug", ch.spread * k, ch.noise * k);
    }
  }
  if (o.navigation) {
    const navfilter::Result& r = *o.navigation;
    std::printf("  uncertainty reduction sqrt(P0/Pk) per state (1 = the data said nothing):\n");
    for (const navfilter::Block& b : navfilter::state::kAll) {
      std::printf("    %-24s", b.name);
      for (int i = 0; i < b.size; ++i) {
        const double s0 = r.sigma0[b.index + i], s1 = r.sigma_final[b.index + i];
        std::printf(" %8.1f", s1 > 0 ? s0 / s1 : 0.0);
      }
      std::printf("\n");
    }
    std::printf("  relative gyro delays: tau_yx %.3f us (sigma %.3f), tau_zx %.3f us (sigma %.3f)\n", r.tau_yx_s * 1e6,
                r.sigma_tau_yx_s * 1e6, r.tau_zx_s * 1e6, r.sigma_tau_zx_s * 1e6);
  }
}

// The calibration pipeline (pipeline/) over a stored run: the stages asked, in order, each from
// the model of the ones before; what they leave (history, curves, reports) stored with the run.
int cmd_calibrate(const CalibrateArgs& a) {
  auto db = storage::RunDb::open(a.db);
  const ImuModel start = a.model.empty() ? ImuModel{} : read_imu_model_file(a.model);
  const bool all = a.stage == "all";
  std::vector<pipeline::Stage> stages;
  if (all) {
    for (const pipeline::StageName& n : pipeline::stage_names()) stages.push_back(n.stage);
  } else {
    stages.push_back(pipeline::stage_named(a.stage).value());
  }
  pipeline::Settings settings;
  settings.passes = a.passes;
  settings.statics_per_cycle = a.statics_per_cycle;
  settings.thermal_T_ref_C = a.t_ref_C;
  settings.thermal_range_lo_C = a.range_C.at(0);
  settings.thermal_range_hi_C = a.range_C.at(1);
  settings.thermal_keep_shape = a.keep_shape;
  // Stage 1 never integrates a rotation across a gap; list them so the operator knows why one is left out.
  if (std::find(stages.begin(), stages.end(), pipeline::Stage::Direct) != stages.end())
    for (const auto& g : storage::stored_gaps(db))
      std::fprintf(stderr, "gap in the frames: %.6f s .. %.6f s\n", g.t0_s, g.t1_s);

  const auto t0 = Clock::now();
  pipeline::Pipeline run(db.meta(), stages, !all, start, settings);
  run.advance(pipeline::RunDbSource(db), std::numeric_limits<std::int64_t>::max(), true);
  std::vector<std::string> ran, skipped;
  for (const pipeline::Outcome& o : run.outcomes()) {
    const std::string name = pipeline::names_of(o.stage).name;
    print_outcome(o);
    for (const auto& [key, text] : o.extras) db.set_extra(key, text);
    if ((o.thermal || o.rate_steps || o.warm_up || o.repeatability) && !a.report.empty()) {
      std::ofstream out(a.report);
      if (!out) throw std::runtime_error(a.report + ": cannot write");
      out << (o.thermal ? nlohmann::json::parse(o.thermal->report_json) : o.report().at(o.rate_steps ? "rate_steps" : o.warm_up ? "warm_up" : "repeatability")).dump(1) << "\n";
    }
    if (o.status == pipeline::Status::Done) {
      ran.push_back(name + " on " + o.source);
    } else if (all) {
      // With --stage all a stage the recording cannot support is skipped with its reason; asked
      // for alone, the same reason is an error.
      skipped.push_back(name + ": " + o.message);
    } else {
      throw std::runtime_error(o.message);
    }
  }
  const ImuModel& model = run.model();
  // Stage 3 works and reports in the body frame: it sees gyro-to-accelerometer alignment only.
  const ImuModel out = (a.frame == "body" || model.frame == "body") ? direct::to_body_frame(model) : model;
  write_imu_model_file(out, a.out);
  for (const auto& s : ran) std::printf("ran stage %s\n", s.c_str());
  for (const auto& s : skipped) std::printf("skipped stage %s\n", s.c_str());
  std::printf("wrote %s (%s frame) in %.1f s\n", a.out.c_str(), out.frame.c_str(), seconds_since(t0));
  return 0;
}

int cmd_evaluate(const std::string& db_path, const std::vector<std::string>& models, const std::string& out_path) {
  const auto db = storage::RunDb::open(db_path);
  const RecordingMeta meta = db.meta();
  nlohmann::json report = {{"db", db_path}, {"variants", nlohmann::json::array()}};
  double base_tilt = 0, base_coning = 0;
  for (std::size_t i = 0; i < models.size(); ++i) {
    std::string name = "variant-" + std::to_string(i + 1), path = models[i];
    if (const auto eq = path.find('='); eq != std::string::npos) {
      name = path.substr(0, eq);
      path = path.substr(eq + 1);
    }
    const ImuModel model = read_imu_model_file(path);
    const evaluate::Result r = pipeline::evaluate_recording(meta, pipeline::RunDbSource(db), model);
    nlohmann::json segs = nlohmann::json::array();
    for (const auto& s : r.segments)
      segs.push_back({{"name", s.name}, {"kind", s.kind}, {"t0_s", s.t0_s}, {"t1_s", s.t1_s},
                      {"schuler_amplitude_e_mps", s.schuler_amplitude_e_mps},
                      {"schuler_amplitude_n_mps", s.schuler_amplitude_n_mps},
                      {"implied_accel_error_mps2", s.implied_accel_error_mps2},
                      {"implied_gyro_drift_dph", s.implied_gyro_drift_radps * units::kRadpsToDph},
                      {"max_velocity_error_mps", s.max_velocity_error_mps},
                      {"max_position_error_m", s.max_position_error_m}});
    if (i == 0) {
      base_tilt = r.tilt_amplitude_mps;
      base_coning = r.coning_amplitude_mps;
    }
    auto ratio = [](double base, double v) { return v > 0 ? base / v : 0.0; };
    report["variants"].push_back({{"name", name},
                                  {"model", path},
                                  {"tilt_schuler_amplitude_mps", r.tilt_amplitude_mps},
                                  {"coning_schuler_amplitude_mps", r.coning_amplitude_mps},
                                  {"implied_accel_error_mps2", r.implied_accel_error_mps2},
                                  {"implied_gyro_drift_dph", r.implied_gyro_drift_radps * units::kRadpsToDph},
                                  {"tilt_improvement_over_first", ratio(base_tilt, r.tilt_amplitude_mps)},
                                  {"coning_improvement_over_first", ratio(base_coning, r.coning_amplitude_mps)},
                                  {"segments", segs}});
    std::printf("%-12s tilt Schuler amplitude %.5f m/s (accel error %.2e m/s^2), coning %.5f m/s (drift %.5f deg/h)\n",
                name.c_str(), r.tilt_amplitude_mps, r.implied_accel_error_mps2, r.coning_amplitude_mps,
                r.implied_gyro_drift_radps * units::kRadpsToDph);
  }
  std::ofstream out(out_path);
  if (!out) throw std::runtime_error(out_path + ": cannot write");
  out << report.dump(1) << "\n";
  return 0;
}

// Coefficient by coefficient: estimate, truth, error, sigma, error/sigma (simulated runs).
int cmd_compare(const std::string& model_path, const std::string& truth_path, const std::string& json_out) {
  const ImuModel est = read_imu_model_file(model_path);
  ImuModel truth = read_imu_model_file(truth_path);
  if (est.frame == "body" && truth.frame != "body") truth = direct::to_body_frame(truth);
  const ImuErrorSet sigma = est.sigma.value_or(ImuErrorSet{});
  nlohmann::json rows = nlohmann::json::array();
  std::printf("%-26s %14s %14s %12s %10s %7s\n", "coefficient", "estimate", "truth", "error", "sigma", "err/sig");
  auto row = [&](const std::string& name, double e, double t, double s, double scale) {
    const double err = (e - t) * scale, sig = s * scale;
    // %g: a delay of 0.3 us and a bias of 2e-6 m/s^2 both keep their digits.
    std::printf("%-26s %14.7g %14.7g %12.4g %10.3g %7.2f\n", name.c_str(), e * scale, t * scale, err, sig,
                sig > 0 ? err / sig : 0.0);
    rows.push_back({{"name", name}, {"estimate", e * scale}, {"truth", t * scale}, {"error", err}, {"sigma", sig}});
  };
  const char* ax[3] = {"x", "y", "z"};
  for (int j = 0; j < 3; ++j) {
    const std::string a = ax[j];
    row("gyro.bias_dph." + a, est.gyro.bias_radps[j], truth.gyro.bias_radps[j], sigma.gyro.bias_radps[j], units::kRadpsToDph);
    row("gyro.scale_pos_ppm." + a, est.gyro.scale_pos[j], truth.gyro.scale_pos[j], sigma.gyro.scale_pos[j], 1e6);
    row("gyro.scale_neg_ppm." + a, est.gyro.scale_neg[j], truth.gyro.scale_neg[j], sigma.gyro.scale_neg[j], 1e6);
    row("gyro.delay_us." + a, est.gyro.delay_s[j], truth.gyro.delay_s[j], sigma.gyro.delay_s[j], 1e6);
    row("accel.bias_mps2." + a, est.accel.bias_mps2[j], truth.accel.bias_mps2[j], sigma.accel.bias_mps2[j], 1.0);
    row("accel.scale_ppm." + a, est.accel.scale[j], truth.accel.scale[j], sigma.accel.scale[j], 1e6);
    row("accel.delay_us." + a, est.accel.delay_s[j], truth.accel.delay_s[j], sigma.accel.delay_s[j], 1e6);
    row("accel.lever_arm_y_mm." + a, est.accel.lever_arm_y_m[j], truth.accel.lever_arm_y_m[j], sigma.accel.lever_arm_y_m[j], 1e3);
    row("accel.lever_arm_z_mm." + a, est.accel.lever_arm_z_m[j], truth.accel.lever_arm_z_m[j], sigma.accel.lever_arm_z_m[j], 1e3);
  }
  for (const auto& [n, k] : kMisalignmentKeys) {
    row(std::string("gyro.misalignment_arcsec.") + n, est.gyro.misalignment_rad.*k, truth.gyro.misalignment_rad.*k,
        sigma.gyro.misalignment_rad.*k, units::kRadToArcsec);
    row(std::string("accel.misalignment_arcsec.") + n, est.accel.misalignment_rad.*k, truth.accel.misalignment_rad.*k,
        sigma.accel.misalignment_rad.*k, units::kRadToArcsec);
  }
  if (!json_out.empty()) {
    std::ofstream out(json_out);
    if (!out) throw std::runtime_error(json_out + ": cannot write");
    out << nlohmann::json({{"frame", est.frame}, {"rows", rows}}).dump(1) << "\n";
  }
  return 0;
}

struct SimDevicesArgs {
  int table_port = 0, chamber_port = 0;
  std::string imu_socket, imu_link = "imucal-can", truth = "ideal", serial, config_file, framing = "fd";
  std::string table_dialect = "imucal-acl";
  double rate_hz = 1000.0;
  std::uint64_t seed = 1;
};

// The simulated bench as separate devices on real addresses, for imucald's `devices` object (an
// operator's rehearsal, the tests of the configured-devices path). Runs until SIGINT/SIGTERM.
int cmd_sim_devices(const SimDevicesArgs& a) {
  // Taken by sigwait() below: blocked before the devices start their threads, which inherit it.
  const sigset_t signals = daemon::block_termination_signals();

  // The daemon's configuration, when given, says where the bench stands and what the table may
  // do: the simulated IMU must sense the same site the daemon calibrates for.
  const daemon::DaemonConfig config = a.config_file.empty() ? daemon::DaemonConfig{}
                                                            : daemon::load_config_file(a.config_file);
  sim::SimDevicesConfig c;
  for (std::size_t axis = 0; axis < 3; ++axis)
    c.servo.limits[axis].fill(daemon::table_limit_setting(config.table_limits.axis[axis]));
  c.table_port = a.table_port;
  c.table_dialect = a.table_dialect;
  c.chamber_port = a.chamber_port;
  c.chamber_start_C = config.chamber.safe_setpoint_C;
  c.chamber_tau_s = config.sim.chamber_tau_s;
  c.imu_socket_path = a.imu_socket;
  c.imu_link = a.imu_link;
  c.imu.framing = a.framing == "classic" ? drivers::can::Framing::classic : drivers::can::Framing::fd;
  c.imu.rate_hz = a.rate_hz;
  c.imu.seed = a.seed;
  c.imu.truth = a.truth == "ideal" ? ImuModel{} : read_imu_model_file(a.truth);
  c.imu.site = config.site;
  c.imu.temperature_C = config.chamber.safe_setpoint_C;
  c.imu_serial = a.serial.empty() ? "SIM-DEVICES-" + std::to_string(a.seed) : a.serial;
  if (c.imu.framing == drivers::can::Framing::classic && a.rate_hz > drivers::can::kClassicMaxRate_hz)
    throw std::invalid_argument("--framing classic carries at most 200 samples/s; --rate-hz is " + std::to_string(a.rate_hz));

  sim::SimDevices devices(c);
  if (devices.imu_serial_device().empty() && a.imu_socket.empty())
    throw std::invalid_argument("--imu-socket is required for a CAN IMU link ('" + a.imu_link + "')");
  const std::string imu_where = devices.imu_serial_device().empty()
                                    ? a.imu_socket + " (a new simulated IMU for each connection)"
                                    : "serial device " + devices.imu_serial_device() + " (a pseudo-terminal)";
  // stdout: the configuration to paste (a complete file on its own); stderr: what is going on.
  std::printf("{\"devices\": %s}\n", devices.devices_config_json().c_str());
  std::fflush(stdout);
  std::fprintf(stderr,
               "imucal sim-devices: table controller (dialect %s) on 127.0.0.1:%d, chamber controller (Modbus TCP, "
               "map %s) on 127.0.0.1:%d, IMU (%s) at %g Hz on %s; SIGINT or SIGTERM stops\n",
               a.table_dialect.c_str(), devices.table_port(), c.chamber_map.c_str(), devices.chamber_port(), a.imu_link.c_str(), a.rate_hz,
               imu_where.c_str());
  int signal_number = 0;
  sigwait(&signals, &signal_number);
  std::fprintf(stderr, "imucal sim-devices: %s, stopping after %llu IMU link(s)\n",
               signal_number == SIGTERM ? "SIGTERM" : "SIGINT", static_cast<unsigned long long>(devices.imu_links()));
  return 0;
}

// `imucal plan`: the predicted 1-sigma of every coefficient after each stage the program feeds.
int cmd_plan(const std::string& program_arg, const std::string& imu_path, const plan::Options& opt,
             const std::string& json_out) {
  const motion::Program program = motion::load_program(program_arg, motion::TableLimits{});
  const ImuModel imu = read_imu_model_file(imu_path);
  const auto t0 = std::chrono::steady_clock::now();
  const plan::Prediction p = plan::predict(program, imu, opt);
  const double wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const nlohmann::json j = p.to_json();
  std::printf("program %s: %.0f s (%.1f h) at %.0f Hz; predicted 1-sigma after each stage (%.1f s to compute)\n",
              p.program.c_str(), p.duration_s, p.duration_s / 3600.0, p.rate_hz, wall_s);
  // One row per coefficient a stage predicts (a sigma above zero), a column per stage.
  std::vector<std::string> names;
  for (const auto& [stage, e] : j.at("stages").items())
    if (e.contains("estimates"))
      for (const auto& [name, v] : e.at("estimates").items())
        if (v.at(1).get<double>() > 0 && std::find(names.begin(), names.end(), name) == names.end())
          names.push_back(name);
  std::printf("  %-30s", "coefficient");
  for (const auto& [stage, e] : j.at("stages").items()) std::printf(" %14s", stage.c_str());
  std::printf("\n");
  for (const std::string& name : names) {
    std::printf("  %-30s", name.c_str());
    for (const auto& [stage, e] : j.at("stages").items()) {
      if (e.contains("estimates") && e.at("estimates").contains(name)) {
        std::printf(" %14.4g", e.at("estimates").at(name).at(1).get<double>());
      } else {
        std::printf(" %14s", e.value("status", "-") == "done" ? "-" : e.value("status", "-").c_str());
      }
    }
    std::printf("\n");
  }
  for (const auto& [stage, e] : j.at("stages").items())
    if (e.contains("message")) std::printf("  %s: %s\n", stage.c_str(), e.at("message").get<std::string>().c_str());
  if (!p.weak.empty()) std::printf("weakly observable or undetermined:\n");
  for (const plan::Weak& w : p.weak)
    std::printf("  %s %s: %s; needs %s\n", w.stage.c_str(), w.coefficient.c_str(), w.why.c_str(), w.fix.c_str());
  if (!p.from_model.empty()) std::printf("taken from the model (nonlinear terms this program does not determine):\n");
  for (const plan::Weak& w : p.from_model)
    std::printf("  %s: %s; to determine it, %s\n", w.coefficient.c_str(), w.why.c_str(), w.fix.c_str());
  if (!json_out.empty()) {
    std::ofstream out(json_out);
    out << j.dump(1) << "\n";
    if (!out) throw std::runtime_error("cannot write " + json_out);
    std::printf("-> %s\n", json_out.c_str());
  }
  return 0;
}

// `imucal plan --optimize`: the shortest program of the given one's family that meets the targets.
int cmd_plan_optimize(const std::string& program_arg, const std::string& imu_path, const plan::OptimizeOptions& opt,
                      const std::string& target_arg, const std::string& program_out, const std::string& json_out) {
  const motion::TableLimits limits{};
  const std::string program_text = motion::load_program(program_arg, limits).source_json;
  const nlohmann::json program = nlohmann::json::parse(program_text);
  const ImuModel imu = read_imu_model_file(imu_path);
  plan::Targets targets;
  if (target_arg == "seed") {
    targets = plan::seed_targets();
  } else {
    std::ifstream in(target_arg);
    if (!in) throw std::runtime_error("cannot read the targets file " + target_arg);
    const nlohmann::json j = nlohmann::json::parse(in, nullptr, false);
    if (j.is_discarded()) throw std::runtime_error(target_arg + " is not JSON");
    targets = plan::targets_from_json(j);
  }
  std::printf("optimizing %s (%s) for %zu targets at %.0f Hz, budget %.0f s\n", program.value("name", "").c_str(),
              program_arg.c_str(), targets.size(), opt.predict.rate_hz, opt.budget_s);
  plan::OptimizeOptions o = opt;
  o.progress = [](const plan::Candidate& c, int n) {
    std::printf("  [%2d] swings x%.3f, oscillations x%.3f: %6.0f s, worst %.2f of its target (%s)\n", n,
                c.swing_period_factor, c.oscillation_factor, c.duration_s, c.worst_ratio, c.worst_coefficient.c_str());
    std::fflush(stdout);
  };
  const plan::OptimizeResult r = plan::optimize(program, imu, targets, limits, o);
  std::printf("front (duration against the worst sigma/target):\n");
  for (const plan::Candidate& c : r.front) std::printf("  %6.0f s  %.2f\n", c.duration_s, c.worst_ratio);
  for (const std::string& u : r.unmet) std::printf("unmet: %s\n", u.c_str());
  const plan::Candidate& chosen = r.best ? *r.best : r.closest;
  if (r.best)
    std::printf("best: %.0f s (%.0f %% of %.0f s), every target met, worst %.2f (%s); %d programs in %.0f s\n",
                chosen.duration_s, 100.0 * chosen.duration_s / r.reference.duration_s, r.reference.duration_s,
                chosen.worst_ratio, chosen.worst_coefficient.c_str(), r.evaluated, r.wall_s);
  else
    std::printf("no program tried meets every target; closest: %.0f s, worst %.2f (%s)\n", chosen.duration_s,
                chosen.worst_ratio, chosen.worst_coefficient.c_str());
  if (!program_out.empty()) {
    std::ofstream out(program_out);
    out << chosen.program_json << "\n";
    if (!out) throw std::runtime_error("cannot write " + program_out);
    std::printf("-> %s (accepted by simulate, campaign and the builder)\n", program_out.c_str());
  }
  if (!json_out.empty()) {
    nlohmann::json front = nlohmann::json::array();
    for (const plan::Candidate& c : r.front)
      front.push_back({{"duration_s", c.duration_s}, {"worst_ratio", c.worst_ratio}, {"worst", c.worst_coefficient},
                       {"swing_period_factor", c.swing_period_factor}, {"oscillation_factor", c.oscillation_factor}});
    const nlohmann::json j = {{"format", "imucal-plan-optimize/1"}, {"reference_duration_s", r.reference.duration_s},
                              {"met", r.best.has_value()}, {"duration_s", chosen.duration_s},
                              {"worst_ratio", chosen.worst_ratio}, {"ratio_by_group", chosen.ratio_by_group},
                              {"front", front}, {"unmet", r.unmet}, {"evaluated", r.evaluated},
                              {"program", nlohmann::json::parse(chosen.program_json)}};
    std::ofstream out(json_out);
    out << j.dump(1) << "\n";
    if (!out) throw std::runtime_error("cannot write " + json_out);
  }
  return r.best ? 0 : 2;
}

// One line from standard input; on a terminal without echo, after a prompt on stderr.
std::string read_secret(const char* prompt) {
  const bool tty = ::isatty(STDIN_FILENO) != 0;
  termios saved{};
  if (tty) {
    std::fprintf(stderr, "%s", prompt);
    ::tcgetattr(STDIN_FILENO, &saved);
    termios quiet = saved;
    quiet.c_lflag &= ~static_cast<tcflag_t>(ECHO);
    ::tcsetattr(STDIN_FILENO, TCSANOW, &quiet);
  }
  std::string line;
  const bool got = static_cast<bool>(std::getline(std::cin, line));
  if (tty) {
    ::tcsetattr(STDIN_FILENO, TCSANOW, &saved);
    std::fprintf(stderr, "\n");
  }
  if (!got) throw std::runtime_error("no password on standard input");
  if (!line.empty() && line.back() == '\r') line.pop_back();
  return line;
}

// `imucal passwd`: the hash for a user's "password_hash" in imucald's configuration.
int cmd_passwd() {
  const std::string password = read_secret("password: ");
  if (password.size() < 8) throw std::runtime_error("the password must have at least 8 characters");
  if (::isatty(STDIN_FILENO) != 0 && read_secret("again: ") != password) throw std::runtime_error("the two do not match");
  std::printf("%s\n", imucal::daemon::hash_password(password).c_str());
  std::fprintf(stderr, "put it in imucald's configuration as a user's \"password_hash\" (docs/daemon.md)\n");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"imucal: calibration of strapdown IMUs on a three-axis table", "imucal"};
  app.require_subcommand(1);

  SimulateArgs sim_args;
  auto* sim = app.add_subcommand("simulate", "Simulate a motion program with a truth IMU into a run database");
  sim->add_option("--program", sim_args.program, "built-in program name or a program JSON file")->required();
  sim->add_option("--imu", sim_args.imu, "truth imucal-imu-model/1 JSON, or 'ideal'")->capture_default_str();
  sim->add_option("--db", sim_args.db, "output run database (must not exist)")->required();
  sim->add_option("--rate", sim_args.rate_hz, "IMU rate, Hz")->capture_default_str()->check(CLI::PositiveNumber);
  sim->add_option("--seed", sim_args.seed, "noise seed")->capture_default_str();
  sim->add_option("--duration", sim_args.duration_s, "stop after this many seconds (0: whole program)")
      ->check(CLI::NonNegativeNumber);
  sim->add_option("--azimuth", sim_args.azimuth_deg, "middle-axis azimuth, deg clockwise from North")
      ->capture_default_str();
  sim->add_option("--chamber", sim_args.chamber,
                  "chamber profile (built-in thermal, thermal-short, or a JSON file): temperatures and the truth's "
                  "thermal section drive the run");
  sim->add_flag("--stabilise", sim_args.stabilise, "with --chamber: the IMU's own thermal stabilisation (relay heater at 55 C: 0.4 C range, 16-30 min control cycle)");
  sim->add_option("--temp-fault", sim_args.temp_faults,
                  "with --chamber: a logged-temperature fault channel:kind:t0_s[:t1_s[:jump_C]] (kind stuck, jump, "
                  "missing; channel gx..az, gx1..gz8, chamber, all)");
  sim->add_option("--chamber-reach-C", sim_args.chamber_reach_C, "with --chamber: the lowest and highest air "
                  "temperature the chamber can reach")->expected(2);
  sim->add_option("--r0-mm", sim_args.r0_mm, "IMU origin from the axis intersection, platform frame, mm")
      ->expected(3);

  NavigateArgs nav_args;
  auto* navc = app.add_subcommand("navigate", "Free-inertial navigation of a run against the table reference");
  navc->add_option("--db", nav_args.db, "run database")->required()->check(CLI::ExistingFile);
  navc->add_option("--model", nav_args.model, "imucal-imu-model/1 to compensate with (default: none)")
      ->check(CLI::ExistingFile);
  navc->add_option("--out", nav_args.out, "CSV of the horizontal errors over time")->required();
  navc->add_option("--summary-json", nav_args.summary_json, "summary (duration, max errors) as JSON");
  navc->add_option("--interval", nav_args.interval_s, "CSV row interval, s")->capture_default_str()->check(
      CLI::PositiveNumber);

  std::string exp_db, exp_dir;
  auto* exp = app.add_subcommand("export", "Write a run as an imucal-recording/1 bundle");
  exp->add_option("--db", exp_db, "run database")->required()->check(CLI::ExistingFile);
  exp->add_option("--out", exp_dir, "output folder")->required();

  std::string imp_dir, imp_db;
  auto* imp = app.add_subcommand("import", "Read an imucal-recording/1 bundle into a run database");
  imp->add_option("dir", imp_dir, "bundle folder (meta.json, frames.csv)")->required()->check(CLI::ExistingDirectory);
  imp->add_option("--db", imp_db, "output run database (must not exist)")->required();

  CalibrateArgs cal_args;
  auto* cal = app.add_subcommand("calibrate", "Estimate the IMU model from a stored run");
  cal->add_option("--db", cal_args.db, "run database")->required()->check(CLI::ExistingFile);
  // The stages as the pipeline names them, in its order: one list for the check and the help.
  std::vector<std::string> stage_choices;
  std::string stage_help;
  for (const pipeline::StageName& n : pipeline::stage_names()) {
    stage_choices.emplace_back(n.name);
    stage_help += std::string(n.name) + ", ";
  }
  stage_choices.emplace_back("all");
  cal->add_option("--stage", cal_args.stage, stage_help + "or all")->capture_default_str()->check(CLI::IsMember(stage_choices));
  cal->add_option("--report", cal_args.report,
                  "stage thermal, rate-steps, warm-up or repeatability: write the stage's report (thermal: residuals, "
                  "degrees, plots; rate-steps: every figure per gyro and rate; warm-up: every channel's transient and "
                  "the bins; repeatability: every channel's figure and each power-on's mean) here");
  cal->add_option("--statics-per-cycle", cal_args.statics_per_cycle,
                  "stage thermal: statics per table cycle, for a run whose statics are not named cycle-NNN/...");
  cal->add_option("--t-ref-C", cal_args.t_ref_C, "stage thermal: reference temperature (default: middle of the data)");
  cal->add_option("--range-C", cal_args.range_C, "stage thermal: the range the run was to cover, C")->expected(2);
  cal->add_flag("--keep-shape", cal_args.keep_shape,
                "stage thermal: keep the model's polynomials and fit only its constants to this run");
  cal->add_option("--model", cal_args.model, "model to start from; its other coefficients are carried over")
      ->check(CLI::ExistingFile);
  cal->add_option("--out", cal_args.out, "output imucal-imu-model/1 JSON")->required();
  cal->add_option("--frame", cal_args.frame, "instrument or body")->capture_default_str()->check(
      CLI::IsMember({"instrument", "body"}));

  cal->add_option("--passes", cal_args.passes, "stage navigation: passes over the recording, each seeded by the last")
      ->capture_default_str()
      ->check(CLI::Range(1, 10));

  std::string eval_db, eval_out;
  std::vector<std::string> eval_models;
  auto* ev = app.add_subcommand("evaluate", "Judge models by free-inertial navigation on an evaluate run (Schuler test)");
  ev->add_option("--db", eval_db, "run of the evaluate program")->required()->check(CLI::ExistingFile);
  ev->add_option("--model", eval_models, "MODEL.json or NAME=MODEL.json; repeat to compare variants (first = baseline)")
      ->required();
  ev->add_option("--out", eval_out, "report JSON")->required();

  imucal::daemon::CampaignRunOptions camp_opts;
  std::string camp_file;
  double camp_time_scale = -1.0;
  bool camp_json = false;
  auto* camp = app.add_subcommand("campaign", "Campaigns through the daemon's sequencer, in-process");
  camp->require_subcommand(1);
  auto* camp_run = camp->add_subcommand(
      "run", "Run a whole campaign on the simulated bench in accelerated time (sequencer, recorder, estimators)");
  camp_run->add_option("file", camp_file, "campaign JSON (docs/api.md, \"Campaign JSON\")")->required()->check(
      CLI::ExistingFile);
  camp_run->add_option("--data-dir", camp_opts.data_dir, "data directory for the daemon database and the run file")
      ->capture_default_str();
  camp_run->add_option("--config", camp_opts.config_file, "imucald configuration (limits, site)")->check(CLI::ExistingFile);
  camp_run->add_option("--model-out", camp_opts.model_out, "write the resulting imucal-imu-model/1 here");
  camp_run->add_option("--time-scale", camp_time_scale, "program seconds per wall second (default: the campaign's, "
                                                        "else as fast as possible)")
      ->check(CLI::NonNegativeNumber);
  camp_run->add_flag("--json", camp_json, "print the summary as one JSON object");

  std::string cmp_model, cmp_truth, cmp_json;
  auto* cmp = app.add_subcommand("compare", "Compare a calibration result with the truth of a simulated run");
  cmp->add_option("model", cmp_model, "estimated imucal-imu-model/1")->required()->check(CLI::ExistingFile);
  cmp->add_option("truth", cmp_truth, "truth imucal-imu-model/1 (put in the body frame when the model is)")
      ->required()
      ->check(CLI::ExistingFile);
  cmp->add_option("--json", cmp_json, "the table as JSON");

  SimDevicesArgs simdev_args;
  auto* simdev = app.add_subcommand(
      "sim-devices", "Run the simulated table controller, chamber controller and IMU standalone on real addresses "
                     "and print the imucald devices configuration that reaches them (until SIGINT/SIGTERM)");
  simdev->add_option("--table-port", simdev_args.table_port, "TCP port of the table controller on 127.0.0.1 (0: any free)")
      ->capture_default_str()
      ->check(CLI::Range(0, 65535));
  simdev->add_option("--table-dialect", simdev_args.table_dialect,
                     "the table controller's language (imucal-acl or an imucal-table-dialect/1 file)")
      ->capture_default_str();
  simdev->add_option("--chamber-port", simdev_args.chamber_port,
                     "Modbus TCP port of the chamber controller on 127.0.0.1 (0: any free)")
      ->capture_default_str()
      ->check(CLI::Range(0, 65535));
  simdev->add_option("--imu-socket", simdev_args.imu_socket,
                     "Unix SOCK_SEQPACKET socket path a CAN IMU listens on (CAN frame images; a new simulated IMU for "
                     "each connection)");
  simdev->add_option("--imu-link", simdev_args.imu_link,
                     "the IMU's link description (imucal-can, kvh-1750, kvh-1775-b or an imucal-imu-link/1 file); a "
                     "serial one is served on a pseudo-terminal")
      ->capture_default_str();
  simdev->add_option("--rate-hz", simdev_args.rate_hz, "IMU sample rate, Hz")->capture_default_str()->check(
      CLI::Range(1.0, 100000.0));
  simdev->add_option("--framing", simdev_args.framing, "fd or classic (at most 200 Hz)")
      ->capture_default_str()
      ->check(CLI::IsMember({"fd", "classic"}));
  simdev->add_option("--seed", simdev_args.seed, "noise seed of the simulated IMU")->capture_default_str();
  simdev->add_option("--truth", simdev_args.truth, "the simulated IMU's imucal-imu-model/1 JSON, or 'ideal'")
      ->capture_default_str();
  simdev->add_option("--serial", simdev_args.serial, "the IMU serial in the printed configuration (default SIM-DEVICES-SEED)");
  simdev->add_option("--config", simdev_args.config_file,
                     "imucald configuration whose site, table limits and chamber defaults the devices take")
      ->check(CLI::ExistingFile);

  std::string plan_program, plan_imu, plan_json;
  plan::Options plan_opt;
  double plan_table_attitude_arcsec = plan_opt.settings.navigation.attitude_noise_rad * units::kRadToArcsec;
  auto* planc = app.add_subcommand(
      "plan", "Predict the 1-sigma of every coefficient a program will give, before the table moves (the program "
              "simulated with the IMU's noise through the calibration pipeline)");
  planc->add_option("--program", plan_program, "built-in program name or a program JSON file")->required();
  planc->add_option("--imu", plan_imu, "the unit's imucal-imu-model/1 with its noise section")
      ->required()
      ->check(CLI::ExistingFile);
  planc->add_option("--rate", plan_opt.rate_hz, "IMU rate, Hz")->capture_default_str()->check(CLI::PositiveNumber);
  planc->add_option("--seed", plan_opt.seed, "noise seed of the simulation")->capture_default_str();
  // The table's reference accuracy, as stage 3 is told it (docs/stage3.md): it bounds the delays
  // and proof masses the program can determine.
  planc->add_option("--table-attitude-arcsec", plan_table_attitude_arcsec,
                    "1-sigma of the attitude the table's encoders give, arcsec")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  planc->add_option("--table-velocity-mps", plan_opt.settings.navigation.velocity_noise_mps,
                    "1-sigma of the table's reference velocity, m/s")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  planc->add_option("--table-position-m", plan_opt.settings.navigation.position_noise_m,
                    "1-sigma of the table's reference position, m")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  planc->add_option("--json", plan_json, "write the prediction (imucal-plan/1), or with --optimize the search, here");
  bool plan_optimize = false;
  std::string plan_target = "seed", plan_program_out;
  plan::OptimizeOptions plan_search;
  planc->add_flag("--optimize", plan_optimize,
                  "search the program's swing periods and oscillation cycles for the shortest that meets the targets");
  planc->add_option("--target", plan_target, "with --optimize: 'seed' (the seed's stage-3 figures) or a JSON file "
                                             "{\"gyro.bias_dph\": 0.001, ...}")
      ->capture_default_str();
  planc->add_option("--budget-s", plan_search.budget_s, "with --optimize: wall time for the search, s")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  planc->add_option("--write-program", plan_program_out, "with --optimize: write the best program here");

  auto* passwd = app.add_subcommand(
      "passwd", "Print the hash of a password (read from standard input) for a user's password_hash in imucald's "
                "configuration");

  // bench record|read (storage): they run from CLI11's callbacks, inside CLI11_PARSE.
  auto* bench = app.add_subcommand("bench", "Benchmarks of the run storage: bench record, bench read");
  imucal::bench::add_storage_bench_commands(*bench);

  if (const int status = imucal::daemon::parse_command_line(app, argc, argv); status >= 0) return status;
  if (camp_run->parsed()) {
    if (camp_time_scale >= 0) camp_opts.time_scale = camp_time_scale;
    camp_opts.progress = !camp_json;
    const auto r = imucal::daemon::run_campaign_file(camp_file, camp_opts);
    const double speed = r.wall_s > 0 ? r.program_s / r.wall_s : 0.0;
    if (camp_json) {
      nlohmann::json j = {{"id", r.id},           {"state", r.state},       {"program_s", r.program_s},
                          {"wall_s", r.wall_s},   {"speed_factor", speed},  {"frames", r.frames},
                          {"run_db", r.run_db},   {"has_model", r.has_model}, {"results", r.results},
                          {"error", r.error}};
      std::printf("%s\n", j.dump().c_str());
    } else if (r.id == 0) {
      std::fprintf(stderr, "imucal campaign run: %s\n", r.error.c_str());
    } else {
      std::printf("campaign %lld: %s; %.1f s of program in %.2f s (%.0fx real time), %lld frames -> %s\n",
                  static_cast<long long>(r.id), r.state.c_str(), r.program_s, r.wall_s, speed,
                  static_cast<long long>(r.frames), r.run_db.c_str());
      if (!r.error.empty()) std::printf("  error: %s\n", r.error.c_str());
      for (const auto& [name, res] : r.results.items()) std::printf("  %s: %s\n", name.c_str(), res.dump().c_str());
      if (r.has_model && !camp_opts.model_out.empty()) std::printf("  model -> %s\n", camp_opts.model_out.c_str());
    }
    return r.exit_code;
  }
  try {
    if (sim->parsed()) return cmd_simulate(sim_args);
    if (navc->parsed()) return cmd_navigate(nav_args);
    if (cal->parsed()) return cmd_calibrate(cal_args);
    if (ev->parsed()) return cmd_evaluate(eval_db, eval_models, eval_out);
    if (cmp->parsed()) return cmd_compare(cmp_model, cmp_truth, cmp_json);
    if (simdev->parsed()) return cmd_sim_devices(simdev_args);
    if (passwd->parsed()) return cmd_passwd();
    if (planc->parsed()) {
      plan_opt.settings.navigation.attitude_noise_rad = plan_table_attitude_arcsec * units::kArcsecToRad;
      if (plan_optimize) {
        plan_search.predict = plan_opt;
        // Many programs are predicted: 20 Hz unless a rate is given.
        if (planc->count("--rate") == 0) plan_search.predict.rate_hz = 20.0;
        return cmd_plan_optimize(plan_program, plan_imu, plan_search, plan_target, plan_program_out, plan_json);
      }
      return cmd_plan(plan_program, plan_imu, plan_opt, plan_json);
    }
    if (exp->parsed()) {
      const auto db = storage::RunDb::open(exp_db);
      storage::export_bundle(db, exp_dir);
      std::printf("exported %lld frames to %s\n", static_cast<long long>(db.frame_count()), exp_dir.c_str());
      return 0;
    }
    if (imp->parsed()) {
      const storage::ImportReport r = storage::import_bundle(imp_dir, imp_db);
      std::printf("imported %lld frames, %lld temperature samples into %s\n", static_cast<long long>(r.frames),
                  static_cast<long long>(r.temp_samples), imp_db.c_str());
      for (const auto& g : r.gaps)
        std::printf("  gap: %.6f s .. %.6f s (frames.csv line %lld)\n", g.t0_s, g.t1_s, static_cast<long long>(g.line));
      return 0;
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "\nimucal %s: error: %s\n", app.get_subcommands().front()->get_name().c_str(), e.what());
    return 1;
  }
  return 0;
}
