#include "modalwatch/transfer_function.hpp"

#include <algorithm>
#include <cmath>
#include <optional>
#include <stdexcept>

#include "modalwatch/polynomial.hpp"

namespace modalwatch {
namespace {

bool all_finite(const std::vector<double>& v) {
  return std::all_of(v.begin(), v.end(), [](double x) { return std::isfinite(x); });
}

// Sum_i c_i z^{n-i} by Horner (descending powers).
std::complex<double> evaluate_descending(const std::vector<double>& c, std::complex<double> z) {
  std::complex<double> s = 0.0;
  for (double ci : c) s = s * z + ci;
  return s;
}

// The controller in state space, z+ = A z + B e, u = C z + D e, read off the
// DF2T recursion so that its state is exactly DiscreteTransferFunction::state().
struct StateSpace {
  Eigen::MatrixXd A;
  Eigen::VectorXd B;
  Eigen::RowVectorXd C;
  double D = 0.0;
};

StateSpace df2t_state_space(const std::vector<double>& num, const std::vector<double>& den) {
  const int n = static_cast<int>(den.size()) - 1;
  StateSpace s;
  s.A = Eigen::MatrixXd::Zero(n, n);
  s.B = Eigen::VectorXd::Zero(n);
  s.C = Eigen::RowVectorXd::Zero(n);
  s.D = num[0];
  if (n == 0) return s;
  s.C(0) = 1.0;
  for (int i = 0; i < n; ++i) {
    s.A(i, 0) = -den[i + 1];
    if (i + 1 < n) s.A(i, i + 1) = 1.0;
    s.B(i) = num[i + 1] - den[i + 1] * num[0];
  }
  return s;
}

}  // namespace

DiscreteTransferFunction::DiscreteTransferFunction(std::vector<double> numerator, std::vector<double> denominator) {
  if (denominator.empty() || denominator.front() == 0.0)
    throw std::invalid_argument("DiscreteTransferFunction: leading denominator coefficient must be != 0");
  if (numerator.empty()) throw std::invalid_argument("DiscreteTransferFunction: empty numerator");
  if (numerator.size() > denominator.size())
    throw std::invalid_argument("DiscreteTransferFunction: improper (numerator degree > denominator degree)");
  if (!all_finite(numerator) || !all_finite(denominator))
    throw std::invalid_argument("DiscreteTransferFunction: non-finite coefficient");
  const double a0 = denominator.front();
  // Right-align: b_0 q^nb + ... with nb < na means leading zeros in q^na .. q^{nb+1}.
  num_.assign(denominator.size() - numerator.size(), 0.0);
  for (double b : numerator) num_.push_back(b / a0);
  den_.reserve(denominator.size());
  for (double a : denominator) den_.push_back(a / a0);
  z_.assign(den_.size() - 1, 0.0);
}

void DiscreteTransferFunction::reset() { std::fill(z_.begin(), z_.end(), 0.0); }

std::complex<double> DiscreteTransferFunction::response(double w, double T) const {
  if (den_.empty()) return 0.0;
  const std::complex<double> z = std::polar(1.0, w * T);
  return evaluate_descending(num_, z) / evaluate_descending(den_, z);
}

void DiscreteTransferFunction::set_state(const std::vector<double>& z) {
  if (z.size() != z_.size()) throw std::invalid_argument("DiscreteTransferFunction::set_state: wrong size");
  z_ = z;
}

double closed_loop_spectral_radius(const DiscreteTransferFunction& controller, const Eigen::MatrixXd& plant_phi,
                                   const Eigen::MatrixXd& plant_gamma, const Eigen::MatrixXd& plant_c, double plant_d) {
  if (controller.empty()) throw std::invalid_argument("closed_loop_spectral_radius: no controller");
  const Eigen::Index np = plant_phi.rows();
  if (plant_phi.cols() != np || plant_gamma.size() != np || plant_c.size() != np)
    throw std::invalid_argument("closed_loop_spectral_radius: plant matrix sizes do not match");
  const Eigen::VectorXd gamma = plant_gamma.reshaped();
  const Eigen::RowVectorXd c = plant_c.reshaped().transpose();
  const StateSpace k = df2t_state_space(controller.numerator(), controller.denominator());
  const Eigen::Index nc = k.A.rows();

  // r = 0: u = C z + D e, e = -(c x + d u)  =>  u = (C z - D c x) / (1 + D d).
  const double s = 1.0 + k.D * plant_d;
  if (s == 0.0) throw std::invalid_argument("closed_loop_spectral_radius: ill-posed loop (1 + D d = 0)");
  const Eigen::RowVectorXd u_x = -k.D * c / s;
  const Eigen::RowVectorXd u_z = k.C / s;
  const Eigen::RowVectorXd e_x = -c - plant_d * u_x;
  const Eigen::RowVectorXd e_z = -plant_d * u_z;

  Eigen::MatrixXd A(np + nc, np + nc);
  A.topLeftCorner(np, np) = plant_phi + gamma * u_x;
  A.topRightCorner(np, nc) = gamma * u_z;
  A.bottomLeftCorner(nc, np) = k.B * e_x;
  A.bottomRightCorner(nc, nc) = k.A + k.B * e_z;
  if (A.size() == 0) return 0.0;
  const std::optional<Eigen::VectorXcd> lambda = eigenvalues(A);
  if (!lambda) throw std::runtime_error("closed_loop_spectral_radius: eigenvalues failed");
  return lambda->cwiseAbs().maxCoeff();
}

}  // namespace modalwatch
