#include "modalwatch/polynomial.hpp"

#include <cmath>
#include <stdexcept>

#include <Eigen/Eigenvalues>

namespace modalwatch {

Eigen::VectorXcd roots(const Eigen::VectorXd& ascending) {
  Eigen::Index n = ascending.size() - 1;
  while (n > 0 && ascending(n) == 0.0) --n;  // drop zero leading coefficients
  if (n <= 0) return Eigen::VectorXcd(0);
  if (n == 1) {
    Eigen::VectorXcd r(1);
    r(0) = -ascending(0) / ascending(1);
    return r;
  }
  if (n == 2) {
    // Closed form, written to avoid cancellation between -b and the root.
    const double c = ascending(0), b = ascending(1), a = ascending(2);
    const double disc = b * b - 4.0 * a * c;
    Eigen::VectorXcd r(2);
    if (disc >= 0.0) {
      const double q = -0.5 * (b + std::copysign(std::sqrt(disc), b));
      r(0) = q / a;
      r(1) = q != 0.0 ? c / q : 0.0;
    } else {
      const double re = -b / (2.0 * a), im = std::sqrt(-disc) / (2.0 * std::abs(a));
      r(0) = {re, im};
      r(1) = {re, -im};
    }
    return r;
  }
  Eigen::MatrixXd companion = Eigen::MatrixXd::Zero(n, n);
  companion.block(1, 0, n - 1, n - 1).setIdentity();
  for (Eigen::Index j = 0; j < n; ++j) companion(j, n - 1) = -ascending(j) / ascending(n);
  Eigen::EigenSolver<Eigen::MatrixXd> solver(companion, false);
  return solver.eigenvalues();
}

std::optional<Eigen::VectorXcd> eigenvalues(const Eigen::MatrixXd& A) {
  const Eigen::EigenSolver<Eigen::MatrixXd> solver(A, false);
  if (solver.info() != Eigen::Success) return std::nullopt;
  return solver.eigenvalues();
}

Eigen::VectorXd polynomial_from_roots(const Eigen::VectorXcd& r, double constant) {
  // Build prod (1 - p/s_k): constant coefficient is 1 by construction, which
  // keeps anti-monic polynomials well scaled whatever the root magnitudes.
  Eigen::VectorXcd c = Eigen::VectorXcd::Zero(r.size() + 1);
  c(0) = 1.0;
  for (Eigen::Index k = 0; k < r.size(); ++k) {
    const std::complex<double> f = -1.0 / r(k);
    for (Eigen::Index j = k + 1; j >= 1; --j) c(j) += f * c(j - 1);
  }
  return c.real() * constant;
}

bool project_stable(Eigen::VectorXd& a, double margin) {
  const Eigen::Index n = a.size();
  if (n == 0) return false;
  if (!a.allFinite() || a(n - 1) == 0.0) return false;
  if (n == 1) {
    if (a(0) > 0.0) return false;
    a(0) = a(0) < 0.0 ? -a(0) : margin;
    return true;
  }
  if (is_hurwitz(a)) return false;
  Eigen::VectorXd asc(n + 1);
  asc(0) = 1.0;
  asc.tail(n) = a;
  Eigen::VectorXcd r = roots(asc);
  for (auto& s : r) {
    if (s.real() > 0.0) {
      s = {-s.real(), s.imag()};
    } else if (s.real() == 0.0 || s.real() > -margin * std::abs(s)) {
      s = {-margin * std::abs(s), s.imag()};
    }
  }
  a = polynomial_from_roots(r, 1.0).tail(n);
  return true;
}

bool is_unstable(const Eigen::VectorXd& a, double tolerance) {
  if (!a.allFinite()) return true;
  if (is_hurwitz(a)) return false;
  Eigen::Index n = a.size();
  while (n > 0 && a(n - 1) == 0.0) --n;  // roots at infinity: the order is lower
  if (n == 0) return false;
  Eigen::VectorXd asc(n + 1);
  asc(0) = 1.0;
  asc.tail(n) = a.head(n);
  const Eigen::VectorXcd r = roots(asc);
  for (const auto& s : r)
    if (s.real() > tolerance * std::abs(s)) return true;
  return false;
}

bool is_hurwitz(const Eigen::VectorXd& a) {
  const Eigen::Index n = a.size();
  if (n == 0) return true;
  // Coefficients in descending order for the Routh array: a_n ... a_1, 1.
  Eigen::VectorXd d(n + 1);
  for (Eigen::Index j = 0; j < n; ++j) d(j) = a(n - 1 - j);
  d(n) = 1.0;
  if (d(0) <= 0.0) return false;
  for (Eigen::Index j = 0; j <= n; ++j)
    if (!(d(j) > 0.0)) return false;
  if (n <= 2) return true;
  // Routh: first column must stay positive.
  const Eigen::Index cols = (n + 2) / 2;
  Eigen::VectorXd r0 = Eigen::VectorXd::Zero(cols), r1 = Eigen::VectorXd::Zero(cols);
  for (Eigen::Index j = 0; j < cols; ++j) {
    if (2 * j <= n) r0(j) = d(2 * j);
    if (2 * j + 1 <= n) r1(j) = d(2 * j + 1);
  }
  for (Eigen::Index row = 2; row <= n; ++row) {
    if (!(r1(0) > 0.0)) return false;
    Eigen::VectorXd r2 = Eigen::VectorXd::Zero(cols);
    for (Eigen::Index j = 0; j + 1 < cols; ++j) r2(j) = (r1(0) * r0(j + 1) - r0(0) * r1(j + 1)) / r1(0);
    r0 = r1;
    r1 = r2;
  }
  return r1(0) > 0.0;
}

}  // namespace modalwatch
