#include "estimators/least_squares.hpp"

#include <cmath>

#include <Eigen/Dense>

namespace imucal::least_squares {

Eigen::VectorXd Fit::sigma() const { return covariance.diagonal().cwiseSqrt(); }

Fit solve(const Eigen::MatrixXd& A, const Eigen::VectorXd& b, const Eigen::VectorXd& w) {
  const Eigen::MatrixXd N = A.transpose() * w.asDiagonal() * A;
  const Eigen::VectorXd rhs = A.transpose() * w.asDiagonal() * b;
  const Eigen::VectorXd scale = N.diagonal().cwiseSqrt().cwiseMax(1e-300);
  const Eigen::MatrixXd Ns = scale.cwiseInverse().asDiagonal() * N * scale.cwiseInverse().asDiagonal();
  const Eigen::LDLT<Eigen::MatrixXd> ldlt(Ns);
  Fit f;
  f.x = scale.cwiseInverse().asDiagonal() * ldlt.solve(scale.cwiseInverse().asDiagonal() * rhs);
  const Eigen::VectorXd r = b - A * f.x;
  f.dof = static_cast<double>(A.rows() - A.cols());
  f.s0sq = f.dof > 0 ? r.dot(w.asDiagonal() * r) / f.dof : 0.0;
  f.normal_inverse = scale.cwiseInverse().asDiagonal() * ldlt.solve(Eigen::MatrixXd::Identity(N.rows(), N.cols())) *
                     scale.cwiseInverse().asDiagonal();
  f.covariance = f.normal_inverse * f.s0sq;
  return f;
}

double chi_square_quantile(double k, double z) {
  const double a = 2.0 / (9.0 * k);
  const double c = 1.0 - a + z * std::sqrt(a);
  return k * c * c * c;
}

double variance_factor(const Fit& fit, double s0sq_noise) {
  if (!(s0sq_noise > 0)) return fit.s0sq;
  if (fit.dof < 1) return s0sq_noise;  // no redundancy to test: the noise is all there is
  constexpr double kNormal99 = 2.3263;  // the normal distribution's 99 % point
  const double limit = chi_square_quantile(fit.dof, kNormal99) / fit.dof;
  return fit.s0sq / s0sq_noise > limit ? fit.s0sq : s0sq_noise;
}

double min_scaled_eigenvalue(const Eigen::MatrixXd& A, const Eigen::VectorXd& w) {
  const Eigen::MatrixXd N = A.transpose() * w.asDiagonal() * A;
  const Eigen::VectorXd s = N.diagonal().cwiseSqrt().cwiseMax(1e-300).cwiseInverse();
  const Eigen::MatrixXd Ns = s.asDiagonal() * N * s.asDiagonal();
  return Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(Ns).eigenvalues().minCoeff();
}

}  // namespace imucal::least_squares
