// The rate-steps test (IEEE Std 952's scale-factor tests for a fibre-optic gyro): each gyro turned
// at a ladder of rates both ways, whole revolutions rest to rest, with statics in the same
// orientation between them. It yields the scale factor at every rate with its sigma, the
// asymmetry, the nonlinearity as IEEE 952 defines it (the largest deviation of the output from the
// least-squares straight line, in ppm of full scale) and the scale_nonlinear_ppm terms of the
// sensor model (CONVENTIONS.md, "Nonlinear terms"), with their degree chosen by how well each
// degree predicts a rate of the ladder left out of its fit (estimators/held_back.hpp, the rule
// stage 2 uses).
// Pure: frames are pushed in, the result comes out.
#pragma once

#include <array>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/imu_model.hpp"
#include "core/recording.hpp"

namespace imucal::rate_steps {

// One rotation of the ladder as the gyro along its axis saw it.
struct Step {
  std::string segment;
  double rate_dps = 0;         // the cruise rate about the gyro's axis (signed), from the table
  double angle_deg = 0;        // the reference angle about the gyro's axis, rest to rest
  double duration_s = 0;
  // The scale error at the cruise rate: what the rotation measured (bias and cross-axis terms
  // removed), an average over its ramps and cruise, moved to the cruise rate by the fitted model.
  double scale_ppm = 0;
  double sigma_ppm = 0;
  double fit_residual_ppm = 0; // this step's scale error minus the fitted model's, over the same rotation
};

struct DegreeScore {
  int degree = 0;
  double held_back_rms_ppm = 0;  // RMS over the steps inside the ladder, each rate predicted without it
};

struct Axis {
  int axis = 0;                   // 0, 1, 2: gyro x, y, z
  bool tested = false;
  std::vector<Step> steps;        // sorted by rate
  double bias_dph = 0, bias_sigma_dph = 0;
  // The model fitted to every step: s_pos|s_neg + c1 q + .. + c_degree q^degree, q = |w| / 100 deg/s.
  double scale_pos_ppm = 0, scale_pos_sigma_ppm = 0;
  double scale_neg_ppm = 0, scale_neg_sigma_ppm = 0;
  double asymmetry_ppm = 0, asymmetry_sigma_ppm = 0;  // scale_pos - scale_neg
  int degree = 0;
  std::array<double, 3> nonlinear_ppm{}, nonlinear_sigma_ppm{};
  std::vector<DegreeScore> scores;
  // IEEE 952: the largest deviation of the steps' outputs from their least-squares straight line,
  // in ppm of the full-scale output (the largest rate of the ladder), and the rate where it is.
  double full_scale_dps = 0;
  double nonlinearity_ppm_fs = 0, nonlinearity_sigma_ppm_fs = 0;
  double nonlinearity_at_dps = 0;
  double residual_rms_ppm = 0;  // of the steps' scale errors about the fitted model
  // Covariance of [scale_pos, scale_neg, c1 .. c_degree], ppm^2.
  Eigen::MatrixXd covariance_ppm2;
  // The fitted model's scale error at a rate (signed, deg/s), and its 1-sigma.
  double scale_ppm_at(double rate_dps, double* sigma_ppm = nullptr) const;
};

struct Result {
  std::array<Axis, 3> axes;
  ImuModel model;  // the prior with every tested gyro's scale_pos, scale_neg and scale_nonlinear replaced, with sigma
  std::vector<std::string> notes;
};

struct Options {
  int max_degree = 3;
  double min_rotation_deg = 300;  // a rate segment must turn at least this much to be a step
};

class RateStepsEstimator {
 public:
  // meta.segments must list the statics and the rate segments (the built-in rate-steps programs do).
  explicit RateStepsEstimator(const RecordingMeta& meta, const Options& options = {});
  ~RateStepsEstimator();
  RateStepsEstimator(const RateStepsEstimator&) = delete;
  RateStepsEstimator& operator=(const RateStepsEstimator&) = delete;
  void push(const ImuFrame& frame);
  // prior: the gyro misalignments that remove the cross-axis Earth rate (a stage-1 model; zero
  // when none is given). Throws std::runtime_error naming what is missing when no gyro was turned
  // at three rates or more.
  Result finish(const ImuModel& prior = {}) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace imucal::rate_steps
