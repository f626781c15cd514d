#include "modalwatch/srivc.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include <Eigen/Eigenvalues>
#include <Eigen/QR>

#include "modalwatch/polynomial.hpp"

namespace modalwatch {
namespace {

// Per-submodel time normalisation: with t' = ws t a mode's
// coefficients become a'_j = a_j ws^j and b'_k = b_k ws^(k+z-l) (p^z B over
// p^l A, z the output's derivatives), so a'_n is of order one whether the
// mode sits at 1 rad/s or at 700 Hz.
double time_scale(const Submodel& s) {
  if (s.n > 0 && s.a(s.n - 1) != 0.0) return std::pow(std::abs(s.a(s.n - 1)), -1.0 / s.n);
  return 1.0;
}

// theta' = scaling .* theta
Eigen::VectorXd scaling(const Submodel& s, double ws) {
  Eigen::VectorXd d(s.n_theta());
  for (int j = 1; j <= s.n; ++j) d(j - 1) = std::pow(ws, j);
  for (int k = 0; k <= s.m; ++k) d(s.n + k) = std::pow(ws, k + s.output_derivatives - s.rigid_poles);
  return d;
}

// One submodel in normalised time: the filter 1/(p^l A') on a signal, and its
// measured output p^z B'/(p^l A') w.
struct ScaledSubmodel {
  const Submodel* shape = nullptr;
  double ws = 1.0;
  Eigen::VectorXd theta;  // normalised

  Eigen::VectorXd a_poly() const {  // [1, a'_1 .. a'_n]
    Eigen::VectorXd c(shape->n + 1);
    c(0) = 1.0;
    c.tail(shape->n) = theta.head(shape->n);
    return c;
  }
  Eigen::VectorXd denominator() const {  // p^l A'
    Eigen::VectorXd c = Eigen::VectorXd::Zero(shape->n + shape->rigid_poles + 1);
    c.tail(shape->n + 1) = a_poly();
    return c;
  }
  // p^z B': the output's numerator over the filter 1/(p^l A').
  Eigen::VectorXd b() const {
    Eigen::VectorXd c = Eigen::VectorXd::Zero(shape->m + shape->output_derivatives + 1);
    c.tail(shape->m + 1) = theta.tail(shape->m + 1);
    return c;
  }
  // Feedthrough of p^z B'/(p^l A'): nonzero only when biproper.
  double feedthrough() const {
    const int N = shape->n + shape->rigid_poles;
    return shape->m + shape->output_derivatives == N ? theta(shape->n + shape->m) / denominator()(N) : 0.0;
  }
};

// B/(p^l A) w at the samples, w held (zoh) or interpolated (foh) between them.
Eigen::VectorXd simulate_scaled(const ScaledSubmodel& s, const Eigen::VectorXd& w, double T, Hold hold = Hold::zoh) {
  Prefilter f(s.denominator(), s.ws * T, hold);
  const Eigen::VectorXd b = s.b();
  Eigen::VectorXd x(w.size());
  for (Eigen::Index k = 0; k < w.size(); ++k) {
    f.step(w(k));
    x(k) = f.combine(b);
  }
  return x;
}

std::vector<ScaledSubmodel> scale_model(const AdditiveModel& model) {
  std::vector<ScaledSubmodel> out;
  for (const auto& s : model.submodels) {
    ScaledSubmodel z;
    z.shape = &s;
    z.ws = time_scale(s);
    z.theta = s.theta().cwiseProduct(scaling(s, z.ws));
    out.push_back(z);
  }
  return out;
}

void unscale_into(const std::vector<ScaledSubmodel>& scaled, AdditiveModel& model) {
  for (std::size_t i = 0; i < scaled.size(); ++i) {
    auto& s = model.submodels[i];
    s.set_theta(scaled[i].theta.cwiseQuotient(scaling(s, scaled[i].ws)));
  }
}

// The noise-free loop u = C_d(q)(r - y), y = sum_i G_i u, solved sample by
// sample so that a biproper controller around a biproper submodel works too.
void simulate_loop_scaled(const std::vector<ScaledSubmodel>& model, DiscreteTransferFunction controller,
                          const Eigen::VectorXd& r, double T, Eigen::VectorXd& z, Eigen::VectorXd& y) {
  controller.reset();
  std::vector<Prefilter> filters;
  std::vector<Eigen::VectorXd> bs;
  double plant_feedthrough = 0.0;
  for (const auto& s : model) {
    filters.emplace_back(s.denominator(), s.ws * T, Hold::zoh);
    bs.push_back(s.b());
    plant_feedthrough += s.feedthrough();
  }
  const double c0 = controller.feedthrough();
  z.resize(r.size());
  y.resize(r.size());
  for (Eigen::Index k = 0; k < r.size(); ++k) {
    double y_free = 0.0;  // output at t_k for a zero input sample w_k
    for (std::size_t i = 0; i < filters.size(); ++i) {
      filters[i].advance();
      filters[i].complete(0.0);
      y_free += filters[i].combine(bs[i]);
    }
    // u = c0 (r - y_free - D u) + q with q the controller's memory.
    const double q = controller.peek(0.0);
    const double u = (c0 * (r(k) - y_free) + q) / (1.0 + c0 * plant_feedthrough);
    const double yk = y_free + plant_feedthrough * u;
    controller.step(r(k) - yk);
    for (auto& f : filters) f.complete(u);
    z(k) = u;
    y(k) = yk;
  }
}

// Filtered signals of one block for one SRIVC iteration (eqs. 18-20, 33):
// regressor phi, instrument psi and filtered output y_f. A block is one
// submodel, or the submodels that share its A(p) (pole_groups), each on its own
// input: the columns are a_1..a_n, then b_0..b_m of each member in turn. With a
// derivative output p^z the regressor of b_k is the prefiltered input's
// (k+z)-th derivative, p^(k+z) u / (p^l A), the top one algebraic when m + z = n + l.
struct Filtered {
  Eigen::MatrixXd phi, psi;
  Eigen::VectorXd y_f;
};

using Signals = std::vector<const Eigen::VectorXd*>;

Filtered filter_block(const ScaledSubmodel& s, const Eigen::VectorXd& y_tilde, const Signals& u,
                      const Eigen::VectorXd& x_hat, const Signals& z, double T, Hold output_hold, Hold input_hold) {
  const int n = s.shape->n, m = s.shape->m, members = static_cast<int>(u.size());
  const int nt = n + members * (m + 1);
  const int derivatives = s.shape->output_derivatives;  // z of p^z
  const double Ts = s.ws * T;
  const Eigen::VectorXd a = s.a_poly(), den = s.denominator();
  Prefilter fy(a, Ts, output_hold), fx(a, Ts, output_hold);
  std::vector<Prefilter> fu, fz;
  for (int q = 0; q < members; ++q) {
    fu.emplace_back(den, Ts, input_hold);
    fz.emplace_back(den, Ts, input_hold);
  }
  const Eigen::Index N = y_tilde.size();
  Filtered out;
  out.phi.resize(N, nt);
  out.psi.resize(N, nt);
  out.y_f.resize(N);
  for (Eigen::Index k = 0; k < N; ++k) {
    const auto& dy = fy.step(y_tilde(k));
    const auto& dx = fx.step(x_hat(k));
    out.y_f(k) = dy(0);
    for (int j = 1; j <= n; ++j) {
      out.phi(k, j - 1) = -dy(j);
      out.psi(k, j - 1) = -dx(j);
    }
    for (int q = 0; q < members; ++q) {
      const auto& du = fu[q].step((*u[q])(k));
      const auto& dz = u[q] == z[q] ? du : fz[q].step((*z[q])(k));
      const int c = n + q * (m + 1);
      for (int j = 0; j <= m; ++j) {
        out.phi(k, c + j) = du(j + derivatives);
        out.psi(k, c + j) = dz(j + derivatives);
      }
    }
  }
  return out;
}

// Solves (sum psi phi^T) theta = sum psi y_f with column equilibration.
// eq. (8) over samples [first, N): the earlier ones only bring the filters up to date.
Eigen::VectorXd iv_solve(const Filtered& f, Eigen::Index first) {
  const Eigen::Index used = f.psi.rows() - first;
  const Eigen::MatrixXd R = f.psi.bottomRows(used).transpose() * f.phi.bottomRows(used);
  const Eigen::VectorXd rhs = f.psi.bottomRows(used).transpose() * f.y_f.tail(used);
  Eigen::VectorXd colscale = R.colwise().norm().transpose();
  for (auto& c : colscale) c = c > 0.0 ? 1.0 / c : 1.0;
  const Eigen::VectorXd scaled = (R * colscale.asDiagonal()).colPivHouseholderQr().solve(rhs);
  return scaled.cwiseProduct(colscale);
}

// Trust region on the natural frequency of a block per iteration: far from the
// solution, a block's residual can be dominated by a neighbouring mode whose own
// block is still wrong, and an undamped step lands the block on that mode (two
// blocks on one mode: a local minimum of the block-coordinate descent). Moving
// sqrt(a_n) by at most a factor `max_step` per iteration lets each block walk to
// its own mode. Returns true when the step was shortened.
bool damp_step(int n, const Eigen::VectorXd& previous, Eigen::VectorXd& theta, double max_step) {
  if (n == 0 || !(max_step > 1.0)) return false;
  const double before = previous(n - 1), after = theta(n - 1);
  if (!(before > 0.0) || !(after > 0.0)) return false;
  const double ratio = std::abs(std::log(after / before)) / n;  // log of the frequency ratio
  const double limit = std::log(max_step);
  if (ratio <= limit) return false;
  theta = previous + (limit / ratio) * (theta - previous);
  return true;
}

double relative_change(const Eigen::VectorXd& now, const Eigen::VectorXd& before) {
  return (now - before).norm() / std::max(before.norm(), 1e-300);
}

}  // namespace

Eigen::MatrixXd FitResult::theta_covariance(int i) const {
  const int o = model.offset(i), n = model.submodels[i].n_theta();
  return covariance.block(o, o, n, n);
}

double fit_percent(const Eigen::VectorXd& y, const Eigen::VectorXd& y_hat) {
  const double den = (y.array() - y.mean()).matrix().norm();
  return den > 0.0 ? 100.0 * (1.0 - (y - y_hat).norm() / den) : 0.0;
}

Eigen::VectorXd simulate_model(const AdditiveModel& model, const Eigen::VectorXd& u, double T) {
  Eigen::VectorXd y = Eigen::VectorXd::Zero(u.size());
  for (const auto& s : scale_model(model)) y += simulate_scaled(s, u, T);
  return y;
}

Eigen::VectorXd simulate_model(const AdditiveModel& model, const Record& data, Hold input_hold) {
  const double T = data.sample_time();
  Eigen::VectorXd y = Eigen::VectorXd::Zero(data.size());
  for (const auto& s : scale_model(model)) y += simulate_scaled(s, data.input(s.shape->input), T, input_hold);
  return y;
}

void simulate_loop(const AdditiveModel& model, const DiscreteTransferFunction& controller, const Eigen::VectorXd& r,
                   double T, Eigen::VectorXd& z, Eigen::VectorXd& y) {
  simulate_loop_scaled(scale_model(model), controller, r, T, z, y);
}

namespace {

FitResult fit_additive(const Record& data, const AdditiveModel& initial, const SrivcOptions& options);

Eigen::VectorXd multiply(const Eigen::VectorXd& x, const Eigen::VectorXd& y) {
  Eigen::VectorXd z = Eigen::VectorXd::Zero(x.size() + y.size() - 1);
  for (Eigen::Index i = 0; i < x.size(); ++i) z.segment(i, y.size()) += x(i) * y;
  return z;
}

// A second start for a model of K resonant modes: the unfactored K = 1 SRIVC has
// no block coupling, so it cannot put two blocks on one mode. Its partial
// fractions, matched to the blocks by frequency, start the additive fit again.
// Returns false when the unfactored fit does not give K resonant pole pairs.
bool unfactored_start(const Record& data, const AdditiveModel& initial, const SrivcOptions& options,
                      AdditiveModel& start) {
  const std::size_t K = initial.submodels.size();
  Eigen::VectorXd A = Eigen::VectorXd::Ones(1);
  for (const auto& s : initial.submodels) A = multiply(A, s.a_polynomial());
  const int n = static_cast<int>(A.size()) - 1;
  Eigen::VectorXd B = Eigen::VectorXd::Zero(n - 1);
  for (std::size_t i = 0; i < K; ++i) {
    Eigen::VectorXd term = initial.submodels[i].b;
    for (std::size_t j = 0; j < K; ++j)
      if (j != i) term = multiply(term, initial.submodels[j].a_polynomial());
    B.head(term.size()) += term;
  }
  Submodel all;
  all.name = "unfactored";
  all.n = n;
  all.m = n - 2;
  all.a = A.tail(n);
  all.b = B;
  all.input = initial.submodels[0].input;
  all.output_derivatives = initial.output_derivatives();
  AdditiveModel k1;
  k1.submodels = {all};
  SrivcOptions o = options;
  o.unfactored_start = false;
  const FitResult fit = fit_additive(data, k1, o);
  const Submodel& g = fit.model.submodels[0];
  if (!g.theta().allFinite()) return false;
  const Eigen::VectorXcd poles = roots(g.a_polynomial());
  std::vector<std::complex<double>> pairs;
  for (const auto& p : poles)
    if (p.imag() > 0.0) pairs.push_back(p);
  if (pairs.size() != K) return false;
  std::sort(pairs.begin(), pairs.end(), [](auto x, auto y) { return std::abs(x) < std::abs(y); });
  std::vector<std::size_t> order(K);
  for (std::size_t i = 0; i < K; ++i) order[i] = i;
  std::sort(order.begin(), order.end(), [&](std::size_t x, std::size_t y) {
    return initial.submodels[x].a(1) > initial.submodels[y].a(1);  // ascending wn
  });
  // Derivative of A (ascending) for the residues B(s)/A'(s).
  const Eigen::VectorXd a_full = g.a_polynomial();
  start = initial;
  for (std::size_t k = 0; k < K; ++k) {
    const std::complex<double> s = pairs[k];
    std::complex<double> num = 0.0, den = 0.0, pk = 1.0;
    for (Eigen::Index j = 0; j < g.b.size(); ++j, pk *= s) num += g.b(j) * pk;
    pk = 1.0;
    for (Eigen::Index j = 1; j < a_full.size(); ++j, pk *= s) den += static_cast<double>(j) * a_full(j) * pk;
    const std::complex<double> c = num / den;
    const double mag2 = std::norm(s);
    Submodel& blk = start.submodels[order[k]];
    blk.a << -2.0 * s.real() / mag2, 1.0 / mag2;
    blk.b << -2.0 * (c * std::conj(s)).real() / mag2;
  }
  return true;
}

}  // namespace

FitResult fit_srivc(const Record& data, const AdditiveModel& initial, const SrivcOptions& options) {
  const Eigen::Index N = data.size();
  if (initial.submodels.empty()) throw std::invalid_argument("fit: the model has no submodels");
  for (const auto& s : initial.submodels) s.check();
  if (options.settle_samples < 0 || options.settle_samples >= N)
    throw std::invalid_argument("fit: " + std::to_string(options.settle_samples) + " settling samples of " +
                                std::to_string(N));
  if (N - options.settle_samples < 2 * initial.n_beta() + 2)
    throw std::invalid_argument("fit: " + std::to_string(N - options.settle_samples) + " samples for " +
                                std::to_string(initial.n_beta()) + " parameters; need at least " +
                                std::to_string(2 * initial.n_beta() + 2));
  if (options.closed_loop && (!data.has_reference() || options.controller.empty()))
    throw std::invalid_argument("fit: closed loop needs the reference r in the data and a controller");
  bool one_input = true;
  for (const auto& s : initial.submodels) {
    if (s.input < 0 || s.input >= data.inputs())
      throw std::invalid_argument("fit: submodel " + s.name + " is driven by input " + std::to_string(s.input + 1) +
                                  " of " + std::to_string(data.inputs()) + " in the record");
    if (data.input(s.input).size() != N)
      throw std::invalid_argument("fit: input " + std::to_string(s.input + 1) + " is not as long as the record");
    one_input = one_input && s.input == initial.submodels[0].input;
  }
  if (options.closed_loop && options.input_hold != Hold::zoh)
    throw std::invalid_argument(
        "fit: a closed loop's input is the controller's held output; input_hold foh is for open loop");
  if (options.closed_loop && !one_input)
    throw std::invalid_argument(
        "fit: a closed loop has the controller's one input; submodels on several inputs "
        "are fitted in open loop only");
  FitResult best = fit_additive(data, initial, options);
  const std::size_t K = initial.submodels.size();
  // The unfactored start is one transfer function: from one input only.
  bool eligible = options.unfactored_start && one_input && K >= 2 && 2 * K <= static_cast<std::size_t>(kMaxFilterOrder);
  for (const auto& s : initial.submodels) eligible = eligible && s.is_mode();
  if (!eligible) return best;
  AdditiveModel start;
  if (!unfactored_start(data, initial, options, start)) return best;
  FitResult other = fit_additive(data, start, options);
  other.start = "unfactored";
  // The lower output error wins (the cost both starts minimise).
  if (other.model.beta().allFinite() && other.noise_variance < best.noise_variance) return other;
  return best;
}

namespace {

// A free initial state (SrivcOptions::free_initial_state). The model's state
// at the fitted part's start, as impulses on each input over the settling part
// (one per state of the submodels on it, spread over it): their amplitudes
// are the least-squares fit of the model's responses to them to its output
// error over the fitted part, where a model started at rest lacks the plant's
// free response from the state it had there.
struct FreeStart {
  Eigen::VectorXd forced;        // the model's output from rest on the record's inputs
  Eigen::MatrixXd basis;         // its responses to the impulses, over the whole record
  Eigen::VectorXd amplitude;     // of each impulse (empty: no estimate, too few samples)
  std::vector<Eigen::Index> at;  // each impulse's sample
  std::vector<int> input;        // and input
  Eigen::VectorXd free() const { return amplitude.size() ? Eigen::VectorXd(basis * amplitude) : Eigen::VectorXd(); }
};

FreeStart free_start(const Record& data, const std::vector<ScaledSubmodel>& model, Eigen::Index first, Hold in_hold) {
  const Eigen::Index N = data.size(), used = N - first;
  const double T = data.sample_time();
  FreeStart f;
  f.forced = Eigen::VectorXd::Zero(N);
  for (const auto& s : model) f.forced += simulate_scaled(s, data.input(s.shape->input), T, in_hold);
  std::vector<Eigen::Index> states(static_cast<std::size_t>(data.inputs()), 0);
  for (const auto& s : model) states[static_cast<std::size_t>(s.shape->input)] += s.shape->n + s.shape->rigid_poles;
  Eigen::Index columns = 0;
  for (const Eigen::Index n : states) columns += n;
  if (columns == 0 || first < columns || used <= 4 * columns) return f;
  f.basis = Eigen::MatrixXd::Zero(N, columns);
  Eigen::VectorXd impulse = Eigen::VectorXd::Zero(N);
  for (int c = 0, col = 0; c < data.inputs(); ++c) {
    const Eigen::Index n = states[static_cast<std::size_t>(c)];
    for (Eigen::Index j = 0; j < n; ++j, ++col) {
      f.at.push_back(first - 1 - j * std::max<Eigen::Index>(1, first / n));
      f.input.push_back(c);
      impulse(f.at.back()) = 1.0;
      for (const auto& s : model)
        if (s.shape->input == c) f.basis.col(col) += simulate_scaled(s, impulse, T, in_hold);
      impulse(f.at.back()) = 0.0;
    }
  }
  const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(f.basis.bottomRows(used));
  f.amplitude = qr.solve(data.y.tail(used) - f.forced.tail(used));
  if (!f.amplitude.allFinite()) f.amplitude.resize(0);
  return f;
}

// The output the regressions see with a free initial state: over the fitted
// part the record's less the model's free response, over the settling part
// the model's own output from rest, so that the prefilters enter the fitted
// part on a trajectory the model could have had, not on the plant's before a
// change. Consistent with the record's inputs from rest, as the fit's
// simulation is.
Eigen::VectorXd output_from_rest(const Record& data, const FreeStart& f, Eigen::Index first) {
  Eigen::VectorXd y = f.forced;
  const Eigen::Index used = data.size() - first;
  y.tail(used) = data.y.tail(used);
  if (f.amplitude.size()) y.tail(used) -= f.free().tail(used);
  return y;
}

// The same record as the model started in its estimated state sees it: the
// impulses added to the inputs, and the settling part's output the model's.
Record with_free_start(const Record& data, const FreeStart& f, Eigen::Index first) {
  Record r = data;
  r.y.head(first) = f.forced.head(first);
  if (!f.amplitude.size()) return r;
  r.y.head(first) += f.free().head(first);
  for (std::size_t k = 0; k < f.at.size(); ++k) {
    Eigen::VectorXd& u = f.input[k] == 0 ? r.u : r.further_u[static_cast<std::size_t>(f.input[k] - 1)];
    u(f.at[k]) += f.amplitude(static_cast<Eigen::Index>(k));
  }
  return r;
}

FitResult fit_additive(const Record& data, const AdditiveModel& initial, const SrivcOptions& options) {
  const Eigen::Index N = data.size();
  const double T = data.sample_time();
  const Eigen::Index first = options.settle_samples, used = N - first;  // the samples in eq. (8)
  const bool free_state = options.free_initial_state && first > 0;
  // The output the regressions see: the record's, or with a free initial
  // state its output from rest (output_from_rest), re-made for each cycle's model.
  Eigen::VectorXd y = data.y;

  FitResult result;
  result.model = initial;
  // Blocks: each submodel, or the submodels that share one A (one resonance on
  // several inputs), whose members start from their leader's A.
  const std::vector<std::vector<int>> groups = pole_groups(result.model);
  for (const auto& g : groups)
    for (int i : g) result.model.submodels[i].a = result.model.submodels[g.front()].a;
  std::vector<ScaledSubmodel> model = scale_model(result.model);
  const std::size_t K = model.size();
  // Each block's regressors come from its members' own inputs (several actuators).
  const auto input_of = [&](int i) -> const Eigen::VectorXd& { return data.input(result.model.submodels[i].input); };
  const auto inputs_of = [&](const std::vector<int>& g) {
    Signals u;
    for (int i : g) u.push_back(&input_of(i));
    return u;
  };

  std::vector<Eigen::VectorXd> x_hat(K);  // G_i u_i: the submodel outputs on the record
  const Hold in_hold = options.input_hold;  // open loop only (checked in fit_srivc)
  for (std::size_t i = 0; i < K; ++i) x_hat[i] = simulate_scaled(model[i], input_of(static_cast<int>(i)), T, in_hold);
  const auto block_output = [&](const std::vector<int>& g) {
    Eigen::VectorXd x = x_hat[static_cast<std::size_t>(g.front())];
    for (std::size_t q = 1; q < g.size(); ++q) x += x_hat[static_cast<std::size_t>(g[q])];
    return x;
  };
  // A block's parameters, [a; b of each member], and back.
  const auto block_theta = [&](const std::vector<int>& g) {
    const ScaledSubmodel& lead = model[static_cast<std::size_t>(g.front())];
    const int n = lead.shape->n, nb = lead.shape->m + 1;
    Eigen::VectorXd theta(n + static_cast<int>(g.size()) * nb);
    theta.head(n) = lead.theta.head(n);
    for (std::size_t q = 0; q < g.size(); ++q)
      theta.segment(n + static_cast<int>(q) * nb, nb) = model[static_cast<std::size_t>(g[q])].theta.tail(nb);
    return theta;
  };
  const auto set_block_theta = [&](const std::vector<int>& g, const Eigen::VectorXd& theta) {
    const int n = model[static_cast<std::size_t>(g.front())].shape->n;
    for (std::size_t q = 0; q < g.size(); ++q) {
      ScaledSubmodel& s = model[static_cast<std::size_t>(g[q])];
      const int nb = s.shape->m + 1;
      s.theta.head(n) = theta.head(n);
      s.theta.tail(nb) = theta.segment(n + static_cast<int>(q) * nb, nb);
    }
  };

  auto beta_scaled = [&] {
    Eigen::VectorXd b(result.model.n_beta());
    for (std::size_t i = 0, o = 0; i < K; o += model[i].theta.size(), ++i)
      b.segment(o, model[i].theta.size()) = model[i].theta;
    return b;
  };

  // Instrument input in closed loop: S_uo r (one input, so every block is one
  // submodel); open loop: each member's own input.
  Eigen::VectorXd z, y_loop;
  // The cycles need not lower the output error every time: with many modes
  // they can pass a good model and wander on (the flexible structure's 467 Hz
  // resonance is held at cycle 10 and lost by cycle 30). With best_cycle a fit
  // that ends without converging returns its cycle of least output error.
  const auto output_error = [&] {
    Eigen::VectorXd e = y;
    for (const auto& x : x_hat) e -= x;
    return e.tail(used).squaredNorm();
  };
  double best_cost = std::numeric_limits<double>::infinity();
  int best_iteration = 0;
  std::vector<Eigen::VectorXd> best_theta(K), best_x_hat(K);
  for (int it = 1; it <= options.max_iterations; ++it) {
    const Eigen::VectorXd before = beta_scaled();
    if (free_state) y = output_from_rest(data, free_start(data, model, first, in_hold), first);
    for (const auto& g : groups) {
      const ScaledSubmodel& lead = model[static_cast<std::size_t>(g.front())];
      const int n = lead.shape->n;
      if (const auto f = static_cast<std::size_t>(g.front()); f < options.frozen.size() && options.frozen[f]) continue;
      for (int s = 0; s < options.srivc_per_block; ++s) {
        // Residual output of this block (eq. 15): the data less the other submodels.
        Eigen::VectorXd y_tilde = y;
        for (std::size_t j = 0; j < K; ++j)
          if (std::find(g.begin(), g.end(), static_cast<int>(j)) == g.end()) y_tilde -= x_hat[j];
        if (options.closed_loop) simulate_loop_scaled(model, options.controller, data.r, T, z, y_loop);
        const Eigen::VectorXd x_hat_z = options.closed_loop ? simulate_scaled(lead, z, T) : block_output(g);
        const Signals u = inputs_of(g);
        const Filtered f = filter_block(lead, y_tilde, u, x_hat_z, options.closed_loop ? Signals{&z} : u, T,
                                        options.output_hold, in_hold);
        Eigen::VectorXd theta = iv_solve(f, first);
        if (!theta.allFinite()) break;  // singular: keep the previous iterate
        if (damp_step(n, block_theta(g), theta, options.max_frequency_step)) ++result.damped_steps;
        if (options.stability_projection && n > 0) {
          Eigen::VectorXd a = theta.head(n);
          if (project_stable(a)) {
            theta.head(n) = a;
            ++result.projections;
          }
        }
        // A p^n coefficient of zero (the projection's roots at infinity, or an
        // unidentifiable direction) is not a model of this order: keep the previous iterate.
        if (n > 0 && !(std::abs(theta(n - 1)) > 0.0)) break;
        set_block_theta(g, theta);
        for (int i : g) {
          const auto k = static_cast<std::size_t>(i);
          x_hat[k] = simulate_scaled(model[k], input_of(i), T, in_hold);
        }
      }
    }
    const double change = relative_change(beta_scaled(), before);
    result.change_history.push_back(change);
    result.iterations = it;
    if (change < options.tolerance) {
      result.converged = true;
      break;
    }
    if (const double cost = output_error(); cost < best_cost) {
      best_cost = cost;
      best_iteration = it;
      for (std::size_t i = 0; i < K; ++i) {
        best_theta[i] = model[i].theta;
        best_x_hat[i] = x_hat[i];
      }
    }
  }
  // Only for a clear gain (1 % of the output error's power): a fit that
  // hovers about its solution keeps its last cycle, as one that converges does.
  if (options.best_cycle && !result.converged && best_iteration > 0 && best_iteration < result.iterations &&
      best_cost < 0.99 * output_error()) {
    for (std::size_t i = 0; i < K; ++i) {
      model[i].theta = best_theta[i];
      x_hat[i] = best_x_hat[i];
    }
    result.best_iteration = best_iteration;
  }
  if (free_state) y = output_from_rest(data, free_start(data, model, first, in_hold), first);
  unscale_into(model, result.model);

  // Output error, noise variance and fit. The free parameters are the blocks':
  // a shared A counts once.
  int free = 0;
  for (const auto& g : groups) free += static_cast<int>(block_theta(g).size());
  result.simulated = Eigen::VectorXd::Zero(N);
  for (const auto& x : x_hat) result.simulated += x;
  const Eigen::VectorXd e = (y - result.simulated).tail(used);
  const int nb = result.model.n_beta();
  // A free initial state is estimated with the parameters.
  Eigen::Index estimated = free;
  if (free_state)
    for (const auto& s : model) estimated += s.shape->n + s.shape->rigid_poles;
  result.noise_variance = e.squaredNorm() / static_cast<double>(std::max<Eigen::Index>(1, used - estimated));
  result.fit_percent = fit_percent(data.y.tail(used), result.simulated.tail(used));

  // Covariance (IV sandwich) over the blocks' parameters: J = sum psi_hat psi^T
  // with psi the output-error gradient (driven by u) and psi_hat the instrument
  // (driven by z); in open loop both coincide and this is sigma^2 (sum psi psi^T)^{-1}.
  // Then onto beta, where a shared A appears once per member (E below).
  if (options.closed_loop) simulate_loop_scaled(model, options.controller, data.r, T, z, y_loop);
  Eigen::MatrixXd Psi(N, free), PsiHat(N, free);
  Eigen::VectorXd D(free);                              // physical = scaled .* D^{-1}
  Eigen::MatrixXd E = Eigen::MatrixXd::Zero(nb, free);  // beta = E * (blocks' parameters)
  for (std::size_t gi = 0, o = 0; gi < groups.size(); ++gi) {
    const auto& g = groups[gi];
    const ScaledSubmodel& lead = model[static_cast<std::size_t>(g.front())];
    const int n = lead.shape->n, mb = lead.shape->m + 1;
    const int nt = n + static_cast<int>(g.size()) * mb;
    const Signals u = inputs_of(g);
    const Signals zi = options.closed_loop ? Signals{&z} : u;
    const Eigen::VectorXd x = block_output(g);
    const Eigen::VectorXd xz = options.closed_loop ? simulate_scaled(lead, z, T) : x;
    // The gradient filters are 1/A on the block's output and 1/(p^l A) on the
    // inputs: exactly the regressor/instrument construction with noise-free signals.
    const Filtered grad = filter_block(lead, x, u, x, u, T, options.output_hold, in_hold);
    const Filtered gh = filter_block(lead, xz, zi, xz, zi, T, options.output_hold, in_hold);
    Psi.middleCols(o, nt) = grad.psi;
    PsiHat.middleCols(o, nt) = gh.psi;  // rows before `first` are dropped below
    const Eigen::VectorXd d = scaling(*lead.shape, lead.ws);
    D.segment(o, n) = d.head(n);
    for (std::size_t q = 0; q < g.size(); ++q) {
      const int bo = result.model.offset(g[q]);
      const int c = static_cast<int>(o) + n + static_cast<int>(q) * mb;
      D.segment(c, mb) = d.tail(mb);
      for (int j = 0; j < n; ++j) E(bo + j, static_cast<int>(o) + j) = 1.0;
      for (int j = 0; j < mb; ++j) E(bo + n + j, c + j) = 1.0;
    }
    o += static_cast<std::size_t>(nt);
  }
  const Eigen::MatrixXd J = PsiHat.bottomRows(used).transpose() * Psi.bottomRows(used);
  const Eigen::MatrixXd S = PsiHat.bottomRows(used).transpose() * PsiHat.bottomRows(used);
  // Instruments from a diverging loop overflow here, if not before.
  result.unstable_loop = options.closed_loop && !(J.allFinite() && S.allFinite());
  {
    // Correlation form, so that the parameters' units do not enter the condition.
    const Eigen::VectorXd d = S.diagonal().cwiseMax(1e-300).cwiseSqrt().cwiseInverse();
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(d.asDiagonal() * S * d.asDiagonal());
    const Eigen::VectorXd& ev = eig.eigenvalues();  // ascending
    result.information_condition =
        eig.info() == Eigen::Success && ev(0) > 0.0 ? ev(free - 1) / ev(0) : std::numeric_limits<double>::infinity();
    result.weakest_direction = E * eig.eigenvectors().col(0);
    if (free != nb) result.weakest_direction.normalize();
  }
  const Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod(J);
  const Eigen::MatrixXd Jinv = cod.pseudoInverse();
  const Eigen::MatrixXd cov_scaled = result.noise_variance * Jinv * S * Jinv.transpose();
  const Eigen::MatrixXd cov_free = D.cwiseInverse().asDiagonal() * cov_scaled * D.cwiseInverse().asDiagonal();
  result.covariance = E * cov_free * E.transpose();
  return result;
}

}  // namespace

Record started_in_state(const Record& data, const AdditiveModel& model, Eigen::Index settle_samples, Hold input_hold) {
  if (settle_samples <= 0 || settle_samples >= data.size()) return data;
  return with_free_start(data, free_start(data, scale_model(model), settle_samples, input_hold), settle_samples);
}

Hold default_output_hold(const AdditiveModel& start, double sample_time) {
  const double fs = 1.0 / sample_time;
  for (const Submodel& s : start.submodels) {
    if (!s.is_mode()) continue;
    const double f = modal_parameters(s).hz() / fs;
    if (f >= kFohFromFraction && f < 0.5) return Hold::foh;
  }
  return Hold::zoh;
}

}  // namespace modalwatch
