#include "modalwatch/model.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <stdexcept>

#include "modalwatch/polynomial.hpp"

namespace modalwatch {

double ModalParameters::hz() const { return wn / (2.0 * std::numbers::pi); }

const char* output_kind_name(int output_derivatives) {
  switch (output_derivatives) {
    case 0:
      return "position";
    case 1:
      return "velocity";
    case 2:
      return "acceleration";
  }
  return "?";
}

std::optional<int> output_derivatives_of(std::string_view kind) {
  for (int z = 0; z <= kMaxOutputDerivatives; ++z)
    if (kind == output_kind_name(z)) return z;
  return std::nullopt;
}

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

Eigen::VectorXd Submodel::output_numerator() const {
  Eigen::VectorXd c = Eigen::VectorXd::Zero(m + output_derivatives + 1);
  c.tail(m + 1) = b;
  return c;
}

std::complex<double> Submodel::response(double w) const {
  const std::complex<double> p(0.0, w);
  // p^z / p^l with the common powers cancelled: exact at w = 0.
  const int l = std::max(rigid_poles - output_derivatives, 0), z = std::max(output_derivatives - rigid_poles, 0);
  std::complex<double> num = 0.0, den = 0.0, pk = 1.0;
  for (Eigen::Index k = 0; k < std::max<Eigen::Index>(n + l + 1, m + z + 1); ++k) {
    if (k >= z && k <= m + z) num += b(k - z) * pk;
    if (k >= l && k <= n + l) den += (k == l ? 1.0 : a(k - l - 1)) * pk;
    pk *= p;
  }
  return num / den;
}

void Submodel::check() const {
  if (n < 0 || m < 0 || rigid_poles < 0) throw std::invalid_argument(name + ": negative order");
  if (output_derivatives < 0 || output_derivatives > kMaxOutputDerivatives)
    throw std::invalid_argument(name + ": the output is position, velocity or acceleration (z = 0, 1, 2)");
  if (m + output_derivatives > n + rigid_poles)
    throw std::invalid_argument(name + (output_derivatives == 0 ? ": m > n + l (improper)"
                                                                 : ": m + z > n + l (improper as " +
                                                                       std::string(output_kind_name(output_derivatives)) + ")"));
  if (a.size() != n || b.size() != m + 1) throw std::invalid_argument(name + ": coefficient sizes do not match n, m");
}

Submodel make_mode(const std::string& name, const ModalParameters& modal, int output_derivatives) {
  Submodel s;
  s.name = name;
  s.output_derivatives = output_derivatives;
  s.n = 2;
  s.m = 0;
  s.a.resize(2);
  s.a << 2.0 * modal.zeta / modal.wn, 1.0 / (modal.wn * modal.wn);
  s.b.resize(1);
  s.b << modal.gain;
  return s;
}

Submodel make_rigid_body(const std::string& name, double gain, int rigid_poles, int output_derivatives) {
  Submodel s;
  s.name = name;
  s.output_derivatives = output_derivatives;
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

Eigen::Matrix3d modal_covariance(double a1, double a2, const Eigen::Matrix3d& c) {
  if (!(a2 > 0.0)) {
    Eigen::Matrix3d out = Eigen::Matrix3d::Zero();
    out(2, 2) = c(2, 2);
    return out;
  }
  // Jacobian of (wn, zeta, gain) w.r.t. (a1, a2, b0).
  const double a2_32 = a2 * std::sqrt(a2);
  Eigen::Matrix3d j = Eigen::Matrix3d::Zero();
  j(0, 1) = -0.5 / a2_32;
  j(1, 0) = 0.5 / std::sqrt(a2);
  j(1, 1) = -0.25 * a1 / a2_32;
  j(2, 2) = 1.0;
  const Eigen::Matrix3d out = j * c * j.transpose();
  return 0.5 * (out + out.transpose());  // exactly symmetric, as a covariance
}

Eigen::Matrix3d modal_covariance(const Submodel& s, const Eigen::MatrixXd& cov) {
  if (cov.rows() != s.n_theta() || cov.cols() != s.n_theta()) return Eigen::Matrix3d::Zero();
  if (!(s.n == 2 && s.a(1) > 0.0)) {
    Eigen::Matrix3d out = Eigen::Matrix3d::Zero();
    out(2, 2) = cov(s.n, s.n);
    return out;
  }
  const std::array<Eigen::Index, 3> at = {0, 1, s.n};  // a1, a2, b0 inside theta
  Eigen::Matrix3d c;
  for (int r = 0; r < 3; ++r)
    for (int k = 0; k < 3; ++k) c(r, k) = cov(at[r], at[k]);
  return modal_covariance(s.a(0), s.a(1), c);
}

ModalParameters modal_std(const Submodel& s, const Eigen::MatrixXd& cov) {
  const Eigen::Matrix3d c = modal_covariance(s, cov);
  return {std::sqrt(std::max(0.0, c(0, 0))), std::sqrt(std::max(0.0, c(1, 1))), std::sqrt(std::max(0.0, c(2, 2)))};
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

std::complex<double> AdditiveModel::response(double w, int input) const {
  std::complex<double> g = 0.0;
  for (const auto& s : submodels)
    if (s.input == input) g += s.response(w);
  return g;
}

bool Submodel::operator==(const Submodel& other) const {
  return name == other.name && n == other.n && m == other.m && rigid_poles == other.rigid_poles &&
         output_derivatives == other.output_derivatives &&
         a.size() == other.a.size() && b.size() == other.b.size() && a == other.a && b == other.b &&
         input == other.input;
}

}  // namespace modalwatch
