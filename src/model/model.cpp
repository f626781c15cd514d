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

Eigen::Matrix3d modal_jacobian(double a1, double a2) {
  Eigen::Matrix3d j = Eigen::Matrix3d::Zero();
  j(2, 2) = 1.0;
  if (!(a2 > 0.0)) return j;
  const double a2_32 = a2 * std::sqrt(a2);
  j(0, 1) = -0.5 / a2_32;
  j(1, 0) = 0.5 / std::sqrt(a2);
  j(1, 1) = -0.25 * a1 / a2_32;
  return j;
}

Eigen::Matrix3d modal_covariance(double a1, double a2, const Eigen::Matrix3d& c) {
  const Eigen::Matrix3d j = modal_jacobian(a1, a2);
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
         output_derivatives == other.output_derivatives && a.size() == other.a.size() && b.size() == other.b.size() &&
         a == other.a && b == other.b && input == other.input && poles_of == other.poles_of;
}

std::vector<std::vector<int>> pole_groups(const AdditiveModel& model) {
  const auto& subs = model.submodels;
  const int K = static_cast<int>(subs.size());
  std::vector<std::vector<int>> groups;
  std::vector<int> group_of(static_cast<std::size_t>(K), -1);
  for (int i = 0; i < K; ++i)
    if (subs[i].poles_of.empty()) {
      group_of[i] = static_cast<int>(groups.size());
      groups.push_back({i});
    }
  for (int i = 0; i < K; ++i) {
    const Submodel& s = subs[i];
    if (s.poles_of.empty()) continue;
    const auto it = std::find_if(subs.begin(), subs.end(), [&](const Submodel& o) { return o.name == s.poles_of; });
    if (it == subs.end())
      throw std::invalid_argument(s.name + ": poles_of names " + s.poles_of + ", which is no submodel of the model");
    const Submodel& leader = *it;
    if (!leader.poles_of.empty())
      throw std::invalid_argument(s.name + ": poles_of names " + leader.name + ", which shares the poles of " +
                                  leader.poles_of + " itself; name " + leader.poles_of);
    if (leader.n != s.n || leader.m != s.m || leader.rigid_poles != s.rigid_poles ||
        leader.output_derivatives != s.output_derivatives)
      throw std::invalid_argument(s.name + ": shares the poles of " + leader.name +
                                  ", so it needs the same orders n, m, rigid poles and output kind");
    std::vector<int>& group = groups[static_cast<std::size_t>(group_of[static_cast<std::size_t>(it - subs.begin())])];
    for (int j : group)
      if (subs[j].input == s.input)
        throw std::invalid_argument(s.name + ": shares the poles of " + leader.name + " on the same input as " +
                                    subs[j].name + "; one resonance has one submodel per input");
    group.push_back(i);
  }
  return groups;
}

namespace {

// Per submodel: the index of the submodel whose a it takes, or -1 for its own.
std::vector<int> leaders(const AdditiveModel& model) {
  std::vector<int> out(model.submodels.size(), -1);
  for (const auto& g : pole_groups(model))
    for (std::size_t q = 1; q < g.size(); ++q) out[static_cast<std::size_t>(g[q])] = g.front();
  return out;
}

}  // namespace

Eigen::MatrixXd free_beta_map(const AdditiveModel& model) {
  const std::vector<int> lead = leaders(model);
  const int K = static_cast<int>(model.submodels.size());
  std::vector<int> free_offset(static_cast<std::size_t>(K));  // where theta_i's first free entry sits
  int free = 0;
  for (int i = 0; i < K; ++i) {
    free_offset[i] = free;
    free += model.submodels[i].n_theta() - (lead[i] >= 0 ? model.submodels[i].n : 0);
  }
  Eigen::MatrixXd E = Eigen::MatrixXd::Zero(model.n_beta(), free);
  for (int i = 0, o = 0; i < K; o += model.submodels[i].n_theta(), ++i) {
    const Submodel& s = model.submodels[i];
    const int own = lead[i] >= 0 ? 0 : s.n;  // a's own entries in the free vector
    for (int j = 0; j < s.n; ++j) E(o + j, lead[i] >= 0 ? free_offset[lead[i]] + j : free_offset[i] + j) = 1.0;
    for (int j = 0; j <= s.m; ++j) E(o + s.n + j, free_offset[i] + own + j) = 1.0;
  }
  return E;
}

Eigen::VectorXd free_beta(const AdditiveModel& model) {
  const std::vector<int> lead = leaders(model);
  Eigen::VectorXd p(model.n_beta());
  int k = 0;
  for (std::size_t i = 0; i < model.submodels.size(); ++i) {
    const Submodel& s = model.submodels[i];
    if (lead[i] < 0) {
      p.segment(k, s.n) = s.a;
      k += s.n;
    }
    p.segment(k, s.m + 1) = s.b;
    k += s.m + 1;
  }
  return p.head(k);
}

void set_free_beta(AdditiveModel& model, const Eigen::VectorXd& p) {
  const std::vector<int> lead = leaders(model);
  int k = 0;
  for (std::size_t i = 0; i < model.submodels.size(); ++i) {
    Submodel& s = model.submodels[i];
    if (lead[i] < 0) {
      s.a = p.segment(k, s.n);
      k += s.n;
    }
    s.b = p.segment(k, s.m + 1);
    k += s.m + 1;
  }
  for (std::size_t i = 0; i < model.submodels.size(); ++i)
    if (lead[i] >= 0) model.submodels[i].a = model.submodels[static_cast<std::size_t>(lead[i])].a;
}

}  // namespace modalwatch
