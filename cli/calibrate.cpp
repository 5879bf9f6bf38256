// imucal calibrate: the calibration pipeline (pipeline/pipeline.hpp) on a stored run, and what each
// stage says.
#include "cli/commands.hpp"

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/expect_value.hpp"
#include "core/imu_model.hpp"
#include "core/units.hpp"
#include "estimators/direct_calibration.hpp"
#include "estimators/nav_filter.hpp"
#include "estimators/thermal.hpp"
#include "pipeline/pipeline.hpp"
#include "storage/bundle.hpp"
#include "storage/run_db.hpp"
#include "cli/progress.hpp"

namespace imucal::cli {

namespace {

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

}  // namespace

// The calibration pipeline (pipeline/) over a stored run: the stages asked, in order, each from
// the model of the ones before; what they leave (history, curves, reports) stored with the run.
int run_calibrate(const CalibrateArgs& a) {
  auto db = storage::RunDb::open(a.db);
  const ImuModel start = a.model.empty() ? ImuModel{} : read_imu_model_file(a.model);
  const bool all = a.stage == "all";
  std::vector<pipeline::Stage> stages;
  if (all) {
    for (const pipeline::StageName& n : pipeline::stage_names()) stages.push_back(n.stage);
  } else {
    // The command line admits only the stages' names and "all" (main.cpp: CLI::IsMember).
    stages.push_back(expect_value(pipeline::stage_named(a.stage), "the stage the command line named"));
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

}  // namespace imucal::cli
