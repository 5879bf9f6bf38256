// imucal navigate: free-inertial navigation of a stored run against the table reference.
#include "cli/commands.hpp"

#include <cstdio>
#include <fstream>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/imu_model.hpp"
#include "core/units.hpp"
#include "estimators/navigation_run.hpp"
#include "storage/run_db.hpp"
#include "cli/progress.hpp"

namespace imucal::cli {

int run_navigate(const NavigateArgs& a) {
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

}  // namespace imucal::cli
