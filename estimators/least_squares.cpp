#include "estimators/least_squares.hpp"

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
  const auto dof = static_cast<double>(A.rows() - A.cols());
  f.s0sq = dof > 0 ? r.dot(w.asDiagonal() * r) / dof : 0.0;
  const Eigen::MatrixXd Ninv = scale.cwiseInverse().asDiagonal() *
                               ldlt.solve(Eigen::MatrixXd::Identity(N.rows(), N.cols())) *
                               scale.cwiseInverse().asDiagonal();
  f.covariance = Ninv * f.s0sq;
  return f;
}

double min_scaled_eigenvalue(const Eigen::MatrixXd& A, const Eigen::VectorXd& w) {
  const Eigen::MatrixXd N = A.transpose() * w.asDiagonal() * A;
  const Eigen::VectorXd s = N.diagonal().cwiseSqrt().cwiseMax(1e-300).cwiseInverse();
  const Eigen::MatrixXd Ns = s.asDiagonal() * N * s.asDiagonal();
  return Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(Ns).eigenvalues().minCoeff();
}

}  // namespace imucal::least_squares
