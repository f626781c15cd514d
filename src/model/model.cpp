#include "modalwatch/model.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>

#include "modalwatch/polynomial.hpp"

namespace modalwatch {

double ModalParameters::hz() const { return wn / (2.0 * std::numbers::pi); }

Eigen::VectorXd Submodel::theta() const {
  Eigen::VectorXd t(n_theta());
  t << a, b;
  return t;
}

void Submodel::set_theta(const Eigen::VectorXd& theta) {
  if (theta.size() != n_theta()) throw std::invalid_argument("Submodel::set_theta: wrong size");
  a = theta.head(n);
  b = theta.tail(m + 1);
}

Eigen::VectorXd Submodel::a_polynomial() const {
  Eigen::VectorXd c(n + 1);
  c(0) = 1.0;
  c.tail(n) = a;
  return c;
}

Eigen::VectorXd Submodel::denominator() const {
  Eigen::VectorXd c = Eigen::VectorXd::Zero(n + rigid_poles + 1);
  c.tail(n + 1) = a_polynomial();
  return c;
}

std::complex<double> Submodel::response(double w) const {
  const std::complex<double> p(0.0, w);
  const Eigen::VectorXd d = denominator();
  std::complex<double> num = 0.0, den = 0.0, pk = 1.0;
  for (Eigen::Index k = 0; k < std::max<Eigen::Index>(d.size(), m + 1); ++k) {
    if (k <= m) num += b(k) * pk;
    if (k < d.size()) den += d(k) * pk;
    pk *= p;
  }
  return num / den;
}

void Submodel::check() const {
  if (n < 0 || m < 0 || rigid_poles < 0) throw std::invalid_argument(name + ": negative order");
  if (m > n + rigid_poles) throw std::invalid_argument(name + ": m > n + l (improper)");
  if (a.size() != n || b.size() != m + 1) throw std::invalid_argument(name + ": coefficient sizes do not match n, m");
}

Submodel make_mode(const std::string& name, const ModalParameters& modal) {
  Submodel s;
  s.name = name;
  s.n = 2;
  s.m = 0;
  s.a.resize(2);
  s.a << 2.0 * modal.zeta / modal.wn, 1.0 / (modal.wn * modal.wn);
  s.b.resize(1);
  s.b << modal.gain;
  return s;
}

Submodel make_rigid_body(const std::string& name, double gain, int rigid_poles) {
  Submodel s;
  s.name = name;
  s.n = 0;
  s.m = 0;
  s.rigid_poles = rigid_poles;
  s.a.resize(0);
  s.b.resize(1);
  s.b << gain;
  return s;
}

ModalParameters modal_parameters(const Submodel& s) {
  ModalParameters p;
  p.gain = s.b.size() > 0 ? s.b(0) : 0.0;
  if (s.n == 2 && s.a(1) > 0.0) {
    p.wn = 1.0 / std::sqrt(s.a(1));
    p.zeta = 0.5 * s.a(0) * p.wn;
  } else if (s.n >= 2) {
    const auto r = resonances(s);
    if (!r.empty()) {
      p.wn = r.front().wn;
      p.zeta = r.front().zeta;
    }
  }
  return p;
}

ModalParameters modal_std(const Submodel& s, const Eigen::MatrixXd& cov) {
  ModalParameters sd;
  if (cov.rows() != s.n_theta()) return sd;
  sd.gain = std::sqrt(std::max(0.0, cov(s.n, s.n)));
  if (s.n == 2 && s.a(1) > 0.0) {
    const double a1 = s.a(0), a2 = s.a(1);
    // Jacobians of wn = a2^{-1/2} and zeta = a1 / (2 sqrt(a2)) w.r.t. (a1, a2).
    Eigen::Vector2d jw(0.0, -0.5 * std::pow(a2, -1.5));
    Eigen::Vector2d jz(0.5 / std::sqrt(a2), -0.25 * a1 * std::pow(a2, -1.5));
    const Eigen::Matrix2d c = cov.topLeftCorner(2, 2);
    sd.wn = std::sqrt(std::max(0.0, jw.dot(c * jw)));
    sd.zeta = std::sqrt(std::max(0.0, jz.dot(c * jz)));
  }
  return sd;
}

std::vector<ModalParameters> resonances(const Submodel& s) {
  std::vector<ModalParameters> out;
  if (s.n == 0) return out;
  const Eigen::VectorXcd r = roots(s.a_polynomial());
  for (const auto& z : r) {
    if (z.imag() < 0.0) continue;  // one of each conjugate pair
    ModalParameters p;
    p.wn = std::abs(z);
    p.zeta = p.wn > 0.0 ? -z.real() / p.wn : 0.0;
    out.push_back(p);
  }
  std::sort(out.begin(), out.end(), [](const auto& x, const auto& y) { return x.wn < y.wn; });
  return out;
}

int AdditiveModel::n_beta() const {
  int n = 0;
  for (const auto& s : submodels) n += s.n_theta();
  return n;
}

Eigen::VectorXd AdditiveModel::beta() const {
  Eigen::VectorXd b(n_beta());
  int o = 0;
  for (const auto& s : submodels) {
    b.segment(o, s.n_theta()) = s.theta();
    o += s.n_theta();
  }
  return b;
}

void AdditiveModel::set_beta(const Eigen::VectorXd& beta) {
  if (beta.size() != n_beta()) throw std::invalid_argument("AdditiveModel::set_beta: wrong size");
  int o = 0;
  for (auto& s : submodels) {
    s.set_theta(beta.segment(o, s.n_theta()));
    o += s.n_theta();
  }
}

int AdditiveModel::offset(int i) const {
  int o = 0;
  for (int j = 0; j < i; ++j) o += submodels[j].n_theta();
  return o;
}

std::complex<double> AdditiveModel::response(double w) const {
  std::complex<double> g = 0.0;
  for (const auto& s : submodels) g += s.response(w);
  return g;
}

bool Submodel::operator==(const Submodel& other) const {
  return name == other.name && n == other.n && m == other.m && rigid_poles == other.rigid_poles &&
         a.size() == other.a.size() && b.size() == other.b.size() && a == other.a && b == other.b;
}

}  // namespace modalwatch
