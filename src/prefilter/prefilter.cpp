#include "modalwatch/prefilter.hpp"

#include <cmath>
#include <stdexcept>

#include <unsupported/Eigen/MatrixFunctions>

namespace modalwatch {
namespace {

// phi_1(z) = (e^z - 1)/z and phi_2(z) = (e^z - 1 - z)/z^2, accurate near 0.
double phi1(double z) { return std::abs(z) < 1e-5 ? 1.0 + z / 2.0 + z * z / 6.0 : std::expm1(z) / z; }
double phi2(double z) {
  if (std::abs(z) < 1e-3) return 0.5 + z / 6.0 + z * z / 24.0 + z * z * z / 120.0;
  return (std::expm1(z) - z) / (z * z);
}

// Controllable canonical form of 1/D(p): x = [w_f, ..., p^{N-1} w_f].
void companion(const Eigen::Ref<const Eigen::VectorXd>& d, FilterMatrix& A, FilterVector& B) {
  const int N = static_cast<int>(d.size()) - 1;
  A.setZero(N, N);
  for (int j = 0; j + 1 < N; ++j) A(j, j + 1) = 1.0;
  for (int j = 0; j < N; ++j) A(N - 1, j) = -d(j) / d(N);
  B.setZero(N);
  B(N - 1) = 1.0 / d(N);
}

Discretization first_order(const Eigen::Ref<const Eigen::VectorXd>& d, double T) {
  Discretization z;
  const double a = -d(0) / d(1), b = 1.0 / d(1), aT = a * T;
  z.phi.setConstant(1, 1, std::exp(aT));
  z.gamma0.setConstant(1, T * phi1(aT) * b);
  z.gamma1.setConstant(1, T * phi2(aT) * b);
  return z;
}

// N = 2, d_0 != 0. exp(A T) = c0 I + c1 A T by Cayley-Hamilton, with c0, c1
// from the eigenvalues of A T (complex, real or repeated); the input integrals
// follow from A^{-1}, or from the Taylor series when |A T| is small (where the
// A^{-1} forms cancel).
Discretization second_order(const Eigen::Ref<const Eigen::VectorXd>& d, double T) {
  FilterMatrix A;
  FilterVector B;
  companion(d, A, B);
  const FilterMatrix AT = A * T;
  const double norm = AT.cwiseAbs().rowwise().sum().maxCoeff();
  Discretization z;
  z.gamma1.setZero(2);
  if (norm < 0.5) {
    // Taylor: phi = sum (AT)^k/k!, Psi0 = sum (AT)^k/(k+1)!, Psi1 = sum (AT)^k/(k+2)!.
    FilterMatrix term = FilterMatrix::Identity(2, 2), phi = FilterMatrix::Zero(2, 2),
                 psi0 = FilterMatrix::Zero(2, 2), psi1 = FilterMatrix::Zero(2, 2);
    double f0 = 1.0, f1 = 1.0, f2 = 0.5;  // 1/k!, 1/(k+1)!, 1/(k+2)!
    for (int k = 0; k < 30; ++k) {
      phi += f0 * term;
      psi0 += f1 * term;
      psi1 += f2 * term;
      term = term * AT;
      f0 /= (k + 1);
      f1 /= (k + 2);
      f2 /= (k + 3);
      if (f0 * std::pow(norm, k + 1) < 1e-18) break;
    }
    z.phi = phi;
    z.gamma0 = T * (psi0 * B);
    z.gamma1 = T * (psi1 * B);
    return z;
  }
  const double tr = AT.trace(), det = AT.determinant();
  const double sigma = 0.5 * tr, disc = sigma * sigma - det;  // eigenvalues sigma +- sqrt(disc)
  const double es = std::exp(sigma);
  double c1;  // sin(w)/w, sinh(w)/w or 1
  double ch;  // cos(w), cosh(w) or 1
  if (disc < -1e-14 * (1.0 + std::abs(det))) {
    const double w = std::sqrt(-disc);
    c1 = std::sin(w) / w;
    ch = std::cos(w);
  } else if (disc > 1e-14 * (1.0 + std::abs(det))) {
    const double w = std::sqrt(disc);
    c1 = std::sinh(w) / w;
    ch = std::cosh(w);
  } else {
    c1 = 1.0;
    ch = 1.0;
  }
  const double k1 = es * c1, k0 = es * (ch - sigma * c1);
  z.phi = k0 * FilterMatrix::Identity(2, 2) + k1 * AT;
  // A^{-1} of the companion matrix [[0, 1], [-d0/d2, -d1/d2]].
  FilterMatrix Ainv(2, 2);
  Ainv << -d(1) / d(0), -d(2) / d(0), 1.0, 0.0;
  const FilterMatrix I = FilterMatrix::Identity(2, 2);
  z.gamma0 = Ainv * ((z.phi - I) * B);
  z.gamma1 = (Ainv * (z.gamma0 - T * B)) / T;
  return z;
}

// General order: exp([[A T, B T, 0], [0, 0, 1], [0, 0, 0]]) = [[phi, g0, g1], ...].
Discretization general(const Eigen::Ref<const Eigen::VectorXd>& d, double T) {
  const int N = static_cast<int>(d.size()) - 1;
  FilterMatrix A;
  FilterVector B;
  companion(d, A, B);
  // Fixed capacity: no heap allocation, so the recursive estimator may call this per sample.
  using Augmented = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxFilterOrder + 2, kMaxFilterOrder + 2>;
  Augmented M = Augmented::Zero(N + 2, N + 2);
  M.topLeftCorner(N, N) = A * T;
  M.block(0, N, N, 1) = B * T;
  M(N, N + 1) = 1.0;
  const Augmented E = M.exp();
  Discretization z;
  z.phi = E.topLeftCorner(N, N);
  z.gamma0 = E.block(0, N, N, 1);
  z.gamma1 = E.block(0, N + 1, N, 1);
  return z;
}

}  // namespace

Discretization discretize(const Eigen::Ref<const Eigen::VectorXd>& d, double T, Hold hold) {
  const int N = static_cast<int>(d.size()) - 1;
  if (N < 0 || N > kMaxFilterOrder) throw std::invalid_argument("discretize: order out of range");
  if (d(N) == 0.0) throw std::invalid_argument("discretize: leading coefficient is zero");
  if (!(T > 0.0)) throw std::invalid_argument("discretize: sample time must be > 0");
  Discretization z;
  if (N == 0) {
    z.phi.resize(0, 0);
    z.gamma0.resize(0);
    z.gamma1.resize(0);
  } else if (N == 1) {
    z = first_order(d, T);
  } else if (N == 2 && d(0) != 0.0) {
    z = second_order(d, T);
  } else {
    z = general(d, T);
  }
  if (hold == Hold::zoh) z.gamma1.setZero(N);
  return z;
}

Prefilter::Prefilter(const Eigen::Ref<const Eigen::VectorXd>& denominator, double T, Hold hold)
    : order_(static_cast<int>(denominator.size()) - 1), T_(T), hold_(hold) {
  d_ = denominator;
  disc_ = discretize(denominator, T, hold);
  x_.setZero(order_);
  out_.setZero(order_ + 1);
}

void Prefilter::set_denominator(const Eigen::Ref<const Eigen::VectorXd>& denominator) {
  if (denominator.size() != order_ + 1) throw std::invalid_argument("Prefilter: order changed");
  d_ = denominator;
  disc_ = discretize(denominator, T_, hold_);
}

void Prefilter::set_denominator(const Eigen::Ref<const Eigen::VectorXd>& denominator,
                                const Discretization& discretization) {
  d_ = denominator;
  disc_ = discretization;
}

void Prefilter::reset() {
  x_.setZero(order_);
  out_.setZero(order_ + 1);
  w_prev_ = 0.0;
}

const FilterVector& Prefilter::step(double w) {
  if (order_ > 0) {
    // x(t_k) from x(t_{k-1}) with the input held (ZOH) or ramped (FOH) over the interval.
    FilterVector next = disc_.phi * x_ + disc_.gamma0 * w_prev_;
    if (hold_ == Hold::foh) next += disc_.gamma1 * (w - w_prev_);
    x_ = next;
  }
  return complete(w);
}

void Prefilter::advance() {
  if (hold_ != Hold::zoh) throw std::logic_error("Prefilter::advance needs a held input (ZOH)");
  if (order_ > 0) {
    FilterVector next = disc_.phi * x_ + disc_.gamma0 * w_prev_;
    x_ = next;
  }
}

const FilterVector& Prefilter::complete(double w) {
  const int N = order_;
  double top = w;
  for (int j = 0; j < N; ++j) {
    out_(j) = x_(j);
    top -= d_(j) * x_(j);
  }
  out_(N) = top / d_(N);
  w_prev_ = w;
  return out_;
}

double Prefilter::combine(const Eigen::Ref<const Eigen::VectorXd>& b) const {
  double s = 0.0;
  for (Eigen::Index j = 0; j < b.size(); ++j) s += b(j) * out_(j);
  return s;
}

void Prefilter::set_state(const FilterVector& x, double previous_input) {
  if (x.size() != order_) throw std::invalid_argument("Prefilter::set_state: wrong size");
  x_ = x;
  w_prev_ = previous_input;
}

}  // namespace modalwatch
