// Weighted least squares with the covariance scaled by the residual variance per unit weight: the
// one solver of the stages that fit coefficients to accumulated intervals (stage 1, the rate-steps
// test, the tumble).
#pragma once

#include <Eigen/Core>

namespace imucal::least_squares {

struct Fit {
  Eigen::VectorXd x;
  Eigen::MatrixXd covariance;  // (A'WA)^-1 s0^2
  double s0sq = 0;             // residual variance per unit weight (0 without redundancy)
  double dof = 0;              // rows - columns
  Eigen::MatrixXd normal_inverse;  // (A'WA)^-1
  Eigen::VectorXd sigma() const;
};

// Rows of A weighted by w. Columns are scaled to unit norm of the normal matrix first, so that the
// solution sees the geometry, not the units. The caller checks the rank (min_scaled_eigenvalue).
Fit solve(const Eigen::MatrixXd& A, const Eigen::VectorXd& b, const Eigen::VectorXd& w);

// The variance per unit weight to scale (A'WA)^-1 with, given the one the sensor's white noise
// alone gives (`s0sq_noise`, measured with thousands of degrees of freedom, e.g. from the scatter
// of the samples within the statics): that one while the residuals are consistent with it (their
// variance factor below the 99 % point of chi-square over the fit's degrees of freedom), the
// residuals' own when they are significantly larger (something beyond the white noise: bias
// instability, the table, an unmodelled term), or when there is no noise figure (0); the noise's
// without redundancy (no residuals to test). The
// residuals' variance factor alone, over the few degrees of freedom of a table program (20-30),
// scatters by 15 % run to run, and the sigma reported with it by up to 30 %.
double variance_factor(const Fit& fit, double s0sq_noise);

// The quantile of chi-square with k degrees of freedom at the normal distribution's quantile z
// (Wilson and Hilferty's cube: within 1 % of the exact value from k = 3); for the test above and
// the repeatability intervals.
double chi_square_quantile(double k, double z);

// The smallest eigenvalue of the normal matrix with unit diagonal: 0 when a combination of the
// columns is not in the data, 1 when the columns are orthogonal.
double min_scaled_eigenvalue(const Eigen::MatrixXd& A, const Eigen::VectorXd& w);

}  // namespace imucal::least_squares
