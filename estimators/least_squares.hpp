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
  Eigen::VectorXd sigma() const;
};

// Rows of A weighted by w. Columns are scaled to unit norm of the normal matrix first, so that the
// solution sees the geometry, not the units. The caller checks the rank (min_scaled_eigenvalue).
Fit solve(const Eigen::MatrixXd& A, const Eigen::VectorXd& b, const Eigen::VectorXd& w);

// The smallest eigenvalue of the normal matrix with unit diagonal: 0 when a combination of the
// columns is not in the data, 1 when the columns are orthogonal.
double min_scaled_eigenvalue(const Eigen::MatrixXd& A, const Eigen::VectorXd& w);

}  // namespace imucal::least_squares
