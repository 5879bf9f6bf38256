// The daemon's estimator worker on a recorded run: the navigation it runs online applies the
// model's thermal section (stage 2) with the run's temperatures, as `imucal navigate` does.
#include <filesystem>

#include <gtest/gtest.h>

#include "../estimators/test_thermal_fixture.hpp"
#include "daemon/subscribers/estimator_worker.hpp"
#include "storage/run_db.hpp"
#include "tests/test_paths.hpp"

using namespace imucal;

TEST(EstimatorWorker, NavigationAppliesTheThermalSection) {
  // Half an hour of the short chamber run, recorded, then navigated by the worker with the truth's
  // section in its model and with the constants alone.
  const thermaltest::ChamberStretch stretch(1800);
  const ImuModel& truth = stretch.truth;
  const motion::Program& program = stretch.program;
  const sim::SimConfig& cfg = stretch.cfg;
  const std::string path = imucaltest::test_tmp_dir() + "/worker-thermal.db";
  std::filesystem::create_directories(imucaltest::test_tmp_dir());
  std::filesystem::remove(path);
  std::int64_t last_t_ns = 0;
  {
    sim::Simulator s(program, truth, cfg);
    auto db = storage::RunDb::create(path, s.meta());
    std::vector<ImuFrame> frames;
    ImuFrame f;
    while (s.next(f)) {
      frames.push_back(f);
      last_t_ns = f.t_ns;
    }
    db.append(frames);
    db.append_temps(s.take_temps());
    db.close();
  }
  // The recorder's commits arrive in steps while the worker tails the file: temperatures after the
  // last frame of one step must wait for the frames of the next.
  auto max_velocity_error = [&](const ImuModel& model) {
    daemon::EstimatorWorker worker(path, {{"navigation"}, model, {}}, std::nullopt, [](auto&&...) {});
    for (std::int64_t t_ns = 0; t_ns < last_t_ns; t_ns += 97'300'000'000) worker.committed(t_ns);
    const auto r = worker.finish(last_t_ns);
    EXPECT_EQ(r.results["navigation"]["status"], "done") << r.results.dump();
    return r.results["navigation"]["max_velocity_error_mps"].get<double>();
  };
  const double with = max_velocity_error(truth), without = max_velocity_error(thermaltest::stage1_of(truth));
  std::printf("worker navigation across a chamber ramp: %.3f m/s compensated, %.3f m/s with the constants\n", with,
              without);
  EXPECT_LT(with, 0.3 * without);
}
