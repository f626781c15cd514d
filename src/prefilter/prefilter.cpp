#include "modalwatch/prefilter.hpp"

#include <algorithm>
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

}  // namespace

namespace detail {

// |A T| >= 2: exp(A T) = c0 I + c1 A T by Cayley-Hamilton, with c0, c1 from the
// eigenvalues of A T (complex, real or repeated), and the input integrals from
// A^{-1}. B = [0, 1/d2].
SecondOrderDiscretization discretize_second_order_closed_form(double d0, double d1, double d2, double T) noexcept {
  const double bB = 1.0 / d2;
  const M2 AT{0.0, T, -d0 / d2 * T, -d1 / d2 * T};
  SecondOrderDiscretization z;
  const double tr = AT.a + AT.d, det = AT.a * AT.d - AT.b * AT.c;
  const double sigma = 0.5 * tr, disc = sigma * sigma - det;  // eigenvalues sigma +- sqrt(disc)
  double k0, k1;                                              // exp(AT) = k0 I + k1 AT
  if (disc > 1e-14 * (1.0 + std::abs(det)) && disc > 1.0) {
    // Real eigenvalues at least 2 apart (a stiff, overdamped filter): from the
    // eigenvalues themselves, k1 = (e^l1 - e^l2)/(l1 - l2) and
    // k0 = (l1 e^l2 - l2 e^l1)/(l1 - l2). e^sigma cosh(w) would overflow to
    // 0 x inf = NaN once w is large (a2 -> 0 with the damping held).
    // The larger-magnitude root without cancellation, the other from l1 l2 = det.
    const double w = std::sqrt(disc);
    const double far = sigma + std::copysign(w, sigma), near = det / far;
    const double l1 = std::max(far, near), l2 = std::min(far, near);
    const double e1 = std::exp(l1), e2 = std::exp(l2);
    k1 = (e1 - e2) / (2.0 * w);
    k0 = (l1 * e2 - l2 * e1) / (2.0 * w);
  } else {
    const double es = std::exp(sigma);
    double c1;  // sin(w)/w, sinh(w)/w or 1
    double ch;  // cos(w), cosh(w) or 1
    if (disc < -1e-14 * (1.0 + std::abs(det))) {
      const double w = std::sqrt(-disc);
      c1 = std::sin(w) / w;  // sin and cos of one argument: one sincos call (GCC)
      ch = std::cos(w);
    } else if (disc > 1e-14 * (1.0 + std::abs(det))) {
      const double w = std::sqrt(disc);
      c1 = std::sinh(w) / w;
      ch = std::cosh(w);
    } else {
      c1 = 1.0;
      ch = 1.0;
    }
    k1 = es * c1;
    k0 = es * (ch - sigma * c1);
  }
  const M2 phi{k0 + k1 * AT.a, k1 * AT.b, k1 * AT.c, k0 + k1 * AT.d};
  // A^{-1} of the companion matrix [[0, 1], [-d0/d2, -d1/d2]] is [[-d1/d0, -d2/d0], [1, 0]].
  const M2 Ainv{-d1 / d0, -d2 / d0, 1.0, 0.0};
  // gamma0 = A^{-1} (phi - I) B, gamma1 = A^{-1} (gamma0 - T B) / T.
  const double v0 = phi.b * bB, v1 = (phi.d - 1.0) * bB;
  const double g0 = Ainv.a * v0 + Ainv.b * v1, g1 = Ainv.c * v0 + Ainv.d * v1;
  const double w0 = g0, w1 = g1 - T * bB;
  z.phi[0][0] = phi.a;
  z.phi[0][1] = phi.b;
  z.phi[1][0] = phi.c;
  z.phi[1][1] = phi.d;
  z.gamma0[0] = g0;
  z.gamma0[1] = g1;
  z.gamma1[0] = (Ainv.a * w0 + Ainv.b * w1) / T;
  z.gamma1[1] = (Ainv.c * w0 + Ainv.d * w1) / T;
  return z;
}

}  // namespace detail

namespace {

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
    const SecondOrderDiscretization s = discretize_second_order(d(0), d(1), d(2), T);
    z.phi.resize(2, 2);
    z.phi << s.phi[0][0], s.phi[0][1], s.phi[1][0], s.phi[1][1];
    z.gamma0.resize(2);
    z.gamma0 << s.gamma0[0], s.gamma0[1];
    z.gamma1.resize(2);
    z.gamma1 << s.gamma1[0], s.gamma1[1];
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

// The state update x <- phi x + gamma0 w_prev (+ gamma1 (w - w_prev)) as plain
// loops: for the orders used here (1..8, mostly 2) Eigen's dynamic-size
// matrix-vector kernel costs more than the arithmetic.
void Prefilter::propagate(double w_next) {
  const int N = order_;
  double next[kMaxFilterOrder];
  const double ramp = hold_ == Hold::foh ? w_next - w_prev_ : 0.0;
  for (int i = 0; i < N; ++i) {
    double v = disc_.gamma0(i) * w_prev_ + disc_.gamma1(i) * ramp;
    for (int j = 0; j < N; ++j) v += disc_.phi(i, j) * x_(j);
    next[i] = v;
  }
  for (int i = 0; i < N; ++i) x_(i) = next[i];
}

const FilterVector& Prefilter::step(double w) {
  propagate(w);
  return complete(w);
}

void Prefilter::advance() {
  if (hold_ != Hold::zoh) throw std::logic_error("Prefilter::advance needs a held input (ZOH)");
  propagate(w_prev_);
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
