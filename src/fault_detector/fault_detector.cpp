#include "modalwatch/fault_detector.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <string>
#include <utility>

#include <Eigen/Cholesky>

// Decisions the header leaves open:
//
// - Validity. An update counts for a mode only when `valid` is true, t is finite
//   and the mode's wn, zeta and gain are all finite; otherwise nothing about that
//   mode changes (flags, pending states, statistics, learning) and its timers are
//   paused: each mode runs on its own clock that advances by t - t_prev only when
//   both this and the previous update were valid for the mode. Hold, clear and
//   learn times and the CUSUMs' time steps are measured on that clock.
// - Statistics. T2 needs S = C + C0 positive definite; otherwise it is 0 and the
//   chi-square path cannot fire. A quantity whose S_qq is not positive and finite
//   reports deviation_sigma 0 and cannot rise; one whose baseline is 0 reports
//   deviation_relative 0 and cannot rise either.
// - The CUSUMs run on the innovations of z_q = d_q / sqrt(C_qq), d_q first shrunk
//   toward 0 by 3 std of the baseline (a baseline's own error is a constant
//   offset that no averaging removes; shifts inside it cannot be told from it).
//   The first valid update after an invalid one only primes the innovation. They
//   are capped at kCusumCap b so that a past excursion is forgotten within
//   (cap - 1) b / k updates, and a quantity's two are reset when its flag falls.
// - A flag falls once the quantity has been out of the reduced box for
//   clear_time: NOT (|z_q| > f sigma_threshold AND |rel_q| > f relative_threshold),
//   f = clear_fraction; a failed test counts as back.
// - Timers: a pending rise starts at the first valid update past the thresholds
//   (evidence_span before it, when that update gives one; or where the relative
//   deviation went past its threshold on the same side and stayed, if earlier:
//   beyond_since_ on the mode clock, its side beyond_up_) and
//   matures at the first valid update at least hold_time (mode clock) later;
//   hold_time = 0 raises at once. Leaving the thresholds cancels it. The clear
//   timer likewise restarts whenever the quantity re-enters the reduced box.
//   below_since_ holds the start of whichever timer runs (rise when unflagged,
//   clear when flagged), on the mode clock; NaN when none does. `since` is the
//   time (t) the condition began while pending, the time the flag rose while
//   flagged, and 0 otherwise.
// - Learning. A window starts at the first valid update of a learning mode and
//   ends at the first valid update at least learn_window (mode clock) later, both
//   ends included; detection starts with the next update. An estimate whose
//   relative std is too large restarts the window at once (learn_hold =
//   uncertain); a window whose halves' means differ restarts at its end
//   (drifting). The baseline is the window's mean; its covariance is the mean
//   reported covariance over n_eff = window / (2 memory_time) independent samples
//   (the integral of the AR(1) correlation exp(-|t|/tau) is 2 tau).
// - update() allocates nothing: all state is sized at construction. It appends at
//   most one change per quantity, 3 * modes per call.

namespace modalwatch {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
// Timers compare elapsed >= duration - kTimeSlack so that, e.g., a 2 s hold at
// 0.1 s updates matures at exactly the 20th update despite rounding in t.
constexpr double kTimeSlack = 1e-9;
// flag_bits() has 64 bits for 3 quantities per mode.
constexpr std::size_t kMaxModes = 64 / kQuantities;
constexpr double kCusumCap = 1.2;
// Shares of the false-alarm rate: the chi-square test and each one-sided CUSUM.
constexpr double kChiShare = 0.5;
constexpr double kCusumShare = 0.5 / (2 * kQuantities);
constexpr double kBaselineBand = 3.0;  // std of the baseline the CUSUMs ignore
constexpr double kChangeSigmas = 3.0;  // a half-window change within this many std is noise
// The relative tests read the estimate as one of a memory this many times
// shorter would give it (the header): a ramp's lag 0.2 memory instead of
// one, at sqrt(5) times the estimate's own scatter.
constexpr double kLeadRatio = 5.0;

const char* quantity_name(int q) {
  static constexpr const char* names[kQuantities] = {"wn", "zeta", "gain"};
  return names[q];
}

Eigen::Vector3d vec(const ModalParameters& p) { return {p.wn, p.zeta, p.gain}; }
ModalParameters params(const Eigen::Vector3d& v) { return {v(0), v(1), v(2)}; }

void set_covariance(ModeBaseline& b, const Eigen::Matrix3d& c) {
  Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(b.covariance.data()) = c;
}

bool finite(const ModalParameters& p) { return std::isfinite(p.wn) && std::isfinite(p.zeta) && std::isfinite(p.gain); }

double normal_tail(double x) { return 0.5 * std::erfc(x / std::numbers::sqrt2); }
double normal_pdf(double x) { return std::exp(-0.5 * x * x) / std::sqrt(2.0 * std::numbers::pi); }

// P(|Y| > a) for Y ~ N(m, I_3), |m| = mu: the radius of Y has the density
// (r / mu) (phi(r - mu) - phi(r + mu)), which integrates in closed form.
double noncentral_chi3_tail(double a, double mu) {
  if (mu < 1e-8) return 2.0 * normal_tail(a) + 2.0 * a * normal_pdf(a);
  return (normal_pdf(a - mu) - normal_pdf(a + mu)) / mu + normal_tail(a - mu) + normal_tail(a + mu);
}

// Expected upcrossings of T2 = |X|^2 past h per update, X a 3-vector AR(1)
// X+ = rho X + s W (s^2 = 1 - rho^2, W ~ N(0, I)) in its stationary state: the
// radius r of X has the chi density sqrt(2/pi) r^2 exp(-r^2/2), and from r the
// next radius exceeds u = sqrt(h) with the noncentral tail above (Simpson in r).
double upcrossings_per_update(double h, double rho) {
  const double s = std::sqrt(1.0 - rho * rho);
  const double u = std::sqrt(h);
  const double lo = std::max(0.0, u - 12.0 * s);
  constexpr int n = 400;  // even
  const double step = (u - lo) / n;
  double sum = 0.0;
  for (int j = 0; j <= n; ++j) {
    const double r = lo + j * step;
    const double f =
        std::sqrt(2.0 / std::numbers::pi) * r * r * std::exp(-0.5 * r * r) * noncentral_chi3_tail(u / s, rho * r / s);
    sum += f * (j == 0 || j == n ? 1.0 : (j % 2 ? 4.0 : 2.0));
  }
  return sum * step / 3.0;
}

// Bisection for a decreasing f: the x in [lo, hi] with f(x) = target.
template <class F>
double solve_decreasing(F f, double target, double lo, double hi) {
  for (int k = 0; k < 200 && hi - lo > 1e-12 * hi; ++k) {
    const double mid = 0.5 * (lo + hi);
    (f(mid) > target ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

void check_thresholds(const FaultThresholds& th, int q) {
  const std::string where = std::string("FaultDetector: thresholds for ") + quantity_name(q) + ": ";
  if (!(std::isfinite(th.sigma_threshold) && th.sigma_threshold > 0.0))
    throw std::invalid_argument(where + "sigma_threshold must be positive");
  if (!(std::isfinite(th.relative_threshold) && th.relative_threshold > 0.0))
    throw std::invalid_argument(where + "relative_threshold must be positive");
  if (!(th.clear_fraction > 0.0 && th.clear_fraction < 1.0))
    throw std::invalid_argument(where + "clear_fraction must lie in (0, 1)");
  if (!(std::isfinite(th.hold_time) && th.hold_time >= 0.0))
    throw std::invalid_argument(where + "hold_time must be >= 0");
  if (!(std::isfinite(th.clear_time) && th.clear_time >= 0.0))
    throw std::invalid_argument(where + "clear_time must be >= 0");
}

void check_positive(double v, const char* name) {
  if (!(std::isfinite(v) && v > 0.0))
    throw std::invalid_argument(std::string("FaultDetector: ") + name + " must be positive");
}

}  // namespace

double chi_square3_tail(double x) {
  if (!(x > 0.0)) return 1.0;
  return std::erfc(std::sqrt(0.5 * x)) + std::sqrt(2.0 * x / std::numbers::pi) * std::exp(-0.5 * x);
}

DetectionThresholds detection_thresholds(const FaultDetectorSettings& s, double memory_time) {
  check_positive(memory_time, "memory_time");
  check_positive(s.update_period, "update_period");
  check_positive(s.false_alarm_interval, "false_alarm_interval");
  check_positive(s.cusum_shift, "cusum_shift");
  const double seconds = 3600.0 * s.false_alarm_interval;
  DetectionThresholds out;

  // Chi-square: h such that T2, with its three components AR(1) with time
  // constant memory_time sampled every update_period, crosses h upward once per
  // seconds / kChiShare on average.
  const double rho = std::exp(-s.update_period / memory_time);
  const double per_update = kChiShare * s.update_period / seconds;
  out.chi_square = solve_decreasing([&](double h) { return upcrossings_per_update(h, rho); }, per_update, 1.0, 2000.0);

  // CUSUM on the innovations of z: e = (z - rho z_prev) / sqrt(1 - rho^2) is
  // N(0, 1) and independent from update to update for AR(1) errors, and a
  // sustained shift delta of z shifts it by delta sqrt((1 - rho) / (1 + rho)),
  // so the reference is k = cusum_shift / 2 times that. Siegmund's approximation
  // of the in-control average run length (in updates) of a one-sided CUSUM of
  // N(0, 1) increments with reference k and threshold b (D. Siegmund, Sequential
  // Analysis, Springer 1985; the 1.166 corrects for the overshoot):
  //   ARL0 = (exp(2 k b') - 1 - 2 k b') / (2 k^2),  b' = b + 1.166.
  out.cusum_reference = 0.5 * s.cusum_shift * std::sqrt((1.0 - rho) / (1.0 + rho));
  const double k = out.cusum_reference;
  const double arl = seconds / kCusumShare / s.update_period;
  const double x = solve_decreasing([](double v) { return -(std::expm1(v) - v); }, -2.0 * k * k * arl, 0.0, 800.0);
  out.cusum = std::max(0.0, x / (2.0 * k) - 1.166);
  return out;
}

FaultDetector::FaultDetector(FaultDetectorSettings settings) : settings_(std::move(settings)) {
  const std::size_t n = settings_.mode_names.size();
  if (n > kMaxModes)
    throw std::invalid_argument("FaultDetector: " + std::to_string(n) + " modes, at most " + std::to_string(kMaxModes) +
                                " fit in the flag bits");
  if (settings_.baselines.size() != n)
    throw std::invalid_argument("FaultDetector: " + std::to_string(settings_.baselines.size()) + " baselines for " +
                                std::to_string(n) + " modes");
  if (!settings_.baseline_std.empty() && settings_.baseline_std.size() != n)
    throw std::invalid_argument("FaultDetector: " + std::to_string(settings_.baseline_std.size()) +
                                " baseline standard deviations for " + std::to_string(n) + " modes");
  check_positive(settings_.learn_window, "learn_window");
  check_positive(settings_.settle_std_fraction, "settle_std_fraction");
  check_positive(settings_.settle_change_fraction, "settle_change_fraction");
  for (int q = 0; q < kQuantities; ++q) check_thresholds(settings_.thresholds[q], q);
  if (!settings_.memory_time.empty() && settings_.memory_time.size() != n)
    throw std::invalid_argument("FaultDetector: " + std::to_string(settings_.memory_time.size()) +
                                " memory times for " + std::to_string(n) + " modes");
  memory_ = settings_.memory_time.empty() ? std::vector<double>(n, kDefaultMemoryTime) : settings_.memory_time;
  if (n == 0) detection_thresholds(settings_, kDefaultMemoryTime);  // checks the other settings all the same
  for (const double memory : memory_) thresholds_.push_back(detection_thresholds(settings_, memory));

  modes_.assign(n, ModeStatus{});
  learning_.assign(n, Learning{});
  cusum_.assign(n, {});
  previous_.assign(n, {kNaN, kNaN, kNaN});
  trend_.assign(n, Eigen::Vector3d::Constant(kNaN));
  below_since_.assign(n, {kNaN, kNaN, kNaN});
  beyond_since_.assign(n, {kNaN, kNaN, kNaN});
  beyond_up_.assign(n, {});
  diagonal_.assign(n, Eigen::Matrix3d::Zero());
  clock_.assign(n, 0.0);
  last_valid_.assign(n, 0);
  testing_.assign(n, 0);
  const auto components = static_cast<Eigen::Index>(kQuantities * n);
  index_.assign(static_cast<std::size_t>(components), 0);
  joint_S_.setZero(components, components);
  joint_Q_.setZero(components, components);
  joint_D_.setZero(components);
  joint_QD_.setZero(components);
  for (std::size_t i = 0; i < n; ++i) {
    const auto& b = settings_.baselines[i];
    if (!b) continue;
    const ModalParameters sd = settings_.baseline_std.empty() ? ModalParameters{} : settings_.baseline_std[i];
    if (!finite(*b) || !finite(sd) || sd.wn < 0.0 || sd.zeta < 0.0 || sd.gain < 0.0)
      throw std::invalid_argument("FaultDetector: configured baseline of mode '" + settings_.mode_names[i] +
                                  "' (or its std) is not finite");
    ModeStatus& m = modes_[i];
    m.baseline.value = *b;
    set_covariance(m.baseline, vec(sd).cwiseAbs2().asDiagonal());
    m.baseline.learned = false;
    m.baseline_ready = true;
    m.state = BaselineState::configured;
  }
}

void FaultDetector::restore_baseline(std::size_t mode, const ModeBaseline& baseline) {
  if (mode >= modes_.size())
    throw std::invalid_argument("FaultDetector: baseline for mode " + std::to_string(mode) + " of " +
                                std::to_string(modes_.size()));
  const bool covariance_finite =
      std::all_of(baseline.covariance.begin(), baseline.covariance.end(), [](double v) { return std::isfinite(v); });
  if (!finite(baseline.value) || !covariance_finite)
    throw std::invalid_argument("FaultDetector: restored baseline of mode '" + settings_.mode_names[mode] +
                                "' (or its covariance) is not finite");
  learning_[mode] = Learning{};
  beyond_since_[mode] = {kNaN, kNaN, kNaN};
  ModeStatus& m = modes_[mode];
  m.baseline = baseline;
  m.baseline_ready = true;
  m.state = baseline.learned ? BaselineState::ready : BaselineState::configured;
  m.learn_progress = baseline.learned ? 1.0 : 0.0;
  m.learn_hold = LearnHold::none;
}

void FaultDetector::restart_learning(std::size_t i, LearnHold why) {
  ModeStatus& m = modes_[i];
  if (learning_[i].count > 0) ++m.learn_restarts;
  learning_[i] = Learning{};
  m.learn_hold = why;
  m.learn_progress = 0.0;
}

void FaultDetector::learn(std::size_t i, double now, const Eigen::Vector3d& x, const Eigen::Matrix3d& c,
                          const Eigen::Matrix3d& settle_c) {
  ModeStatus& m = modes_[i];
  Learning& l = learning_[i];
  for (int q = 0; q < kQuantities; ++q) {
    const double limit = settings_.settle_std_fraction * settings_.thresholds[q].relative_threshold;
    if (!(settle_c(q, q) >= 0.0 && std::sqrt(settle_c(q, q)) < limit * std::abs(x(q)))) {
      restart_learning(i, LearnHold::uncertain);
      return;
    }
  }
  if (l.count == 0) l.start = now;
  const double window = settings_.learn_window;
  const double elapsed = now - l.start;
  ++l.count;
  l.sum += x;
  l.sum_covariance += c;
  if (elapsed < 0.5 * window - kTimeSlack) {
    ++l.count_first;
    l.sum_first += x;
  }
  m.learn_progress = std::min(1.0, elapsed / window);
  if (elapsed < window - kTimeSlack) return;

  const double count = static_cast<double>(l.count);
  const Eigen::Vector3d mean = l.sum / count;
  const Eigen::Matrix3d mean_covariance = l.sum_covariance / count;
  if (l.count_first > 0 && l.count > l.count_first) {
    const Eigen::Vector3d first = l.sum_first / static_cast<double>(l.count_first);
    const Eigen::Vector3d second = (l.sum - l.sum_first) / static_cast<double>(l.count - l.count_first);
    const double half_samples = independent_samples(i, 0.5 * window);
    for (int q = 0; q < kQuantities; ++q) {
      const double change = std::abs(second(q) - first(q));
      const double noise = kChangeSigmas * std::sqrt(2.0 * mean_covariance(q, q) / half_samples);
      const double limit = settings_.settle_change_fraction * settings_.thresholds[q].relative_threshold;
      if (change > limit * std::abs(mean(q)) && change > noise) {
        restart_learning(i, LearnHold::drifting);
        return;
      }
    }
  }
  const double samples = independent_samples(i, window);
  m.baseline.value = params(mean);
  set_covariance(m.baseline, mean_covariance / samples);
  m.baseline.learned = true;
  m.baseline_ready = true;
  m.state = BaselineState::ready;
  m.learn_progress = 1.0;
  m.learn_hold = LearnHold::none;
}

void FaultDetector::name_the_changed_mode(const std::vector<ModalParameters>& value, const Eigen::MatrixXd& joint) {
  const std::size_t n = modes_.size();
  if (joint.rows() != static_cast<Eigen::Index>(kQuantities * n) || joint.cols() != joint.rows()) return;
  // The components with a variance (a rigid body's wn and zeta have none), of
  // modes correlated with another testing mode: one correlated with none keeps
  // its own deviation exactly, and says nothing about the others'.
  const auto correlated = [&](std::size_t i) {
    for (std::size_t j = 0; j < n; ++j)
      if (j != i && testing_[j] &&
          !joint.block<3, 3>(static_cast<Eigen::Index>(kQuantities * i), static_cast<Eigen::Index>(kQuantities * j))
               .isZero(0.0))
        return true;
    return false;
  };
  int m = 0, modes = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (!testing_[i] || !correlated(i)) continue;
    const Eigen::Matrix3d c0 = modes_[i].baseline.covariance_matrix();
    const int before = m;
    for (int q = 0; q < kQuantities; ++q) {
      const auto at = static_cast<Eigen::Index>(kQuantities * i + static_cast<std::size_t>(q));
      const double v = joint(at, at) + c0(q, q);
      if (std::isfinite(v) && v > 0.0) index_[static_cast<std::size_t>(m++)] = static_cast<int>(at);
    }
    modes += m > before;
  }
  if (modes < 2) return;
  auto S = joint_S_.topLeftCorner(m, m);
  auto D = joint_D_.head(m);
  for (int a = 0; a < m; ++a) {
    const int ia = index_[static_cast<std::size_t>(a)];
    const auto mode = static_cast<std::size_t>(ia / kQuantities);
    const Eigen::Matrix3d c0 = modes_[mode].baseline.covariance_matrix();
    D(a) = vec(value[mode])(ia % kQuantities) - vec(modes_[mode].baseline.value)(ia % kQuantities);
    for (int b = 0; b < m; ++b) {
      const int ib = index_[static_cast<std::size_t>(b)];
      S(a, b) = joint(ia, ib) + (ib / kQuantities == ia / kQuantities ? c0(ia % kQuantities, ib % kQuantities) : 0.0);
    }
  }
  if (!S.allFinite() || !D.allFinite()) return;
  Eigen::LLT<Eigen::Ref<Eigen::MatrixXd>> llt(S);  // in place: no allocation
  if (llt.info() != Eigen::Success) return;
  auto Q = joint_Q_.topLeftCorner(m, m);
  Q.setIdentity();
  llt.solveInPlace(Q);
  auto QD = joint_QD_.head(m);
  QD.noalias() = Q.lazyProduct(D);
  // Per mode k, a change of k alone: its estimate (Q_kk)^-1 (Q D)_k and the
  // part of D' S^-1 D it explains, (Q D)_k' (Q_kk)^-1 (Q D)_k.
  double most = 0.0;
  for (int first = 0; first < m;) {
    const int mode = index_[static_cast<std::size_t>(first)] / kQuantities;
    int p = 1;
    while (first + p < m && index_[static_cast<std::size_t>(first + p)] / kQuantities == mode) ++p;
    Eigen::Matrix3d qkk = Eigen::Matrix3d::Identity();  // padded to 3 x 3 with the identity
    qkk.topLeftCorner(p, p) = Q.block(first, first, p, p);
    const Eigen::LLT<Eigen::Matrix3d> small(qkk);
    if (small.info() == Eigen::Success) {
      const Eigen::Matrix3d skk = small.solve(Eigen::Matrix3d::Identity());
      Eigen::Vector3d qd = Eigen::Vector3d::Zero();
      qd.head(p) = QD.segment(first, p);
      const Eigen::Vector3d dk = skk * qd;
      const double explained = qd.dot(dk);
      if (explained > most) {
        most = explained;
        named_ = mode;
        const auto k = static_cast<std::size_t>(mode);
        named_d_ = vec(value[k]) - vec(modes_[k].baseline.value);
        named_S_ = joint.block<3, 3>(kQuantities * mode, kQuantities * mode) + modes_[k].baseline.covariance_matrix();
        for (int a = 0; a < p; ++a) {
          const int qa = index_[static_cast<std::size_t>(first + a)] % kQuantities;
          named_d_(qa) = dk(a);
          for (int b = 0; b < p; ++b)
            named_S_(qa, index_[static_cast<std::size_t>(first + b)] % kQuantities) = skk(a, b);
        }
      }
    }
    first += p;
  }
}

void FaultDetector::update(double t, const std::vector<ModalParameters>& value,
                           const std::vector<ModalParameters>& std_dev, bool valid, std::vector<FlagChange>& changes,
                           double evidence_span) {
  if (std_dev.size() != diagonal_.size())
    throw std::invalid_argument("FaultDetector::update: estimates for a different number of modes");
  for (std::size_t i = 0; i < diagonal_.size(); ++i) {
    const Eigen::Vector3d sd = vec(std_dev[i]);
    for (int q = 0; q < kQuantities; ++q)
      diagonal_[i](q, q) = std::isfinite(sd(q)) && sd(q) > 0.0 ? sd(q) * sd(q) : kNaN;
  }
  update(t, value, diagonal_, valid, changes, evidence_span);
}

void FaultDetector::update(double t, const std::vector<ModalParameters>& value,
                           const std::vector<Eigen::Matrix3d>& covariance, bool valid, std::vector<FlagChange>& changes,
                           double evidence_span, const std::vector<Eigen::Matrix3d>* settle_covariance,
                           const Eigen::MatrixXd* joint, const std::vector<Eigen::Matrix3d>* sampling_covariance) {
  const std::size_t n = modes_.size();
  if (value.size() != n || covariance.size() != n || (settle_covariance && settle_covariance->size() != n) ||
      (sampling_covariance && sampling_covariance->size() != n))
    throw std::invalid_argument("FaultDetector::update: estimates for a different number of modes");
  const bool t_ok = std::isfinite(t);
  const double span = std::isfinite(evidence_span) && evidence_span > 0.0 ? evidence_span : 0.0;
  for (std::size_t i = 0; i < n; ++i)
    testing_[i] = valid && t_ok && finite(value[i]) && modes_[i].state != BaselineState::learning;
  named_ = -1;
  if (joint) name_the_changed_mode(value, *joint);

  for (std::size_t i = 0; i < n; ++i) {
    const bool mode_valid = valid && t_ok && finite(value[i]);
    if (!mode_valid) {
      last_valid_[i] = 0;                 // the interval up to the next valid update does not count
      previous_[i] = {kNaN, kNaN, kNaN};  // nor does the innovation across it
      trend_[i].setConstant(kNaN);        // nor the slope
      continue;
    }
    const double dt = last_valid_[i] && t > last_t_ ? t - last_t_ : 0.0;
    clock_[i] += dt;
    last_valid_[i] = 1;
    const double now = clock_[i];
    ModeStatus& m = modes_[i];
    const Eigen::Vector3d x = vec(value[i]);
    const Eigen::Matrix3d& c = covariance[i];
    // (1 + tau p) / (1 + tau p / r) x = x + (r - 1) (x - trend), trend = x
    // through 1 / (1 + tau p / r): the estimate with its memory's lag undone
    // and a lag of tau / r put back. An estimate fitted on a window, or the
    // first after an invalid spell, has no lag to undo.
    Eigen::Vector3d& trend = trend_[i];
    if (dt > 0.0 && span == 0.0 && trend.allFinite())
      trend += -std::expm1(-dt * kLeadRatio / memory_[i]) * (x - trend);
    else
      trend = x;
    const Eigen::Vector3d x_lead = x + (kLeadRatio - 1.0) * (x - trend);

    if (m.state == BaselineState::learning) {
      learn(i, now, x, c, settle_covariance ? (*settle_covariance)[i] : c);
      continue;
    }

    const Eigen::Vector3d x0 = vec(m.baseline.value);
    const Eigen::Vector3d own = x - x0;  // the estimate's own deviation
    const Eigen::Matrix3d c0 = m.baseline.covariance_matrix();
    // The mode a change of which explains the modes' deviations best is
    // tested given the others (name_the_changed_mode).
    const bool named = named_ == static_cast<int>(i);
    // The relative tests': the lag-free deviation where it says more on the
    // same side, else the estimate's own (a lead that points back says nothing
    // about where the plant is, only that the estimate is moving). Not for a
    // mode whose estimate trades with the named one's: it moves along that
    // trade while the named mode's change settles, and stops short.
    Eigen::Vector3d tested = own;
    const bool trades_with_named =
        named_ >= 0 && !named && joint &&
        !joint->block<3, 3>(kQuantities * static_cast<Eigen::Index>(i), kQuantities * Eigen::Index{named_}).isZero(0.0);
    for (int q = 0; q < kQuantities && !trades_with_named; ++q) {
      const double lead = x_lead(q) - x0(q);
      if (lead * own(q) > 0.0 && std::abs(lead) > std::abs(own(q))) tested(q) = lead;
    }
    const Eigen::Vector3d d = named ? named_d_ : own;
    const Eigen::Matrix3d S = named ? named_S_ : Eigen::Matrix3d(c + c0);
    // The AR(1) coefficient and CUSUM reference over this update's interval.
    const double rho = std::exp(-dt / memory_[i]);
    const double h = thresholds_[i].chi_square, b = thresholds_[i].cusum;
    const double k = 0.5 * settings_.cusum_shift * std::sqrt((1.0 - rho) / (1.0 + rho));
    const Eigen::LLT<Eigen::Matrix3d> llt(S);
    m.chi_square = S.allFinite() && llt.info() == Eigen::Success ? d.dot(llt.solve(d)) : 0.0;
    const bool chi_real = m.chi_square > h;
    // The named mode's own deviation against the estimate's sampling
    // fluctuation and the baseline's share of it: a learned baseline averages
    // window / (2 memory) independent samples of it, a configured one keeps
    // its own covariance.
    Eigen::Matrix3d S_sampling = Eigen::Matrix3d::Zero();
    bool sampling_valid = false, sampling_real = false;
    if (named && sampling_covariance) {
      const Eigen::Matrix3d& f = (*sampling_covariance)[i];
      const double samples = independent_samples(i, settings_.learn_window);
      S_sampling = f + (m.baseline.learned ? Eigen::Matrix3d(f / samples) : c0);
      const Eigen::LLT<Eigen::Matrix3d> sampling_llt(S_sampling);
      sampling_valid = S_sampling.allFinite() && sampling_llt.info() == Eigen::Success;
      if (sampling_valid) {
        const double chi = own.dot(sampling_llt.solve(own));
        sampling_real = chi > h;
        m.chi_square = std::max(m.chi_square, chi);
      }
    }

    for (int q = 0; q < kQuantities; ++q) {
      const FaultThresholds& th = settings_.thresholds[q];
      QuantityStatus& s = m.quantity[q];
      std::array<double, 2 * kQuantities>& g = cusum_[i];

      const bool sigma_ok = std::isfinite(S(q, q)) && S(q, q) > 0.0;
      const bool rel_ok = x0(q) != 0.0;
      s.deviation_sigma = sigma_ok ? d(q) / std::sqrt(S(q, q)) : 0.0;
      const bool sampling_ok = sampling_valid && S_sampling(q, q) > 0.0;
      const double sampling_sigma = sampling_ok ? own(q) / std::sqrt(S_sampling(q, q)) : 0.0;
      s.deviation_relative = rel_ok ? own(q) / std::abs(x0(q)) : 0.0;
      const double tested_relative = rel_ok ? tested(q) / std::abs(x0(q)) : 0.0;
      double& z_prev = previous_[i][q];
      if (std::isfinite(c(q, q)) && c(q, q) > 0.0) {
        const double band = kBaselineBand * std::sqrt(std::max(0.0, c0(q, q)));
        const double shrunk = std::copysign(std::max(0.0, std::abs(own(q)) - band), own(q));
        const double z = shrunk / std::sqrt(c(q, q));
        if (dt > 0.0 && std::isfinite(z_prev)) {
          const double e = (z - rho * z_prev) / std::sqrt(1.0 - rho * rho);
          g[2 * q] = std::clamp(g[2 * q] + e - k, 0.0, kCusumCap * b);
          g[2 * q + 1] = std::clamp(g[2 * q + 1] - e - k, 0.0, kCusumCap * b);
        }
        z_prev = z;
      } else {
        z_prev = kNaN;
      }
      s.cusum = std::max(g[2 * q], g[2 * q + 1]) / b;
      const bool cusum_real = (g[2 * q] > b && own(q) > 0.0) || (g[2 * q + 1] > b && own(q) < 0.0);

      const double ds = std::abs(s.deviation_sigma), dr = std::abs(tested_relative);
      const double dss = std::abs(sampling_sigma);
      const bool real = (chi_real && sigma_ok && ds > th.sigma_threshold) || cusum_real;
      const bool same_side = (d(q) > 0.0) == (own(q) > 0.0);
      const bool sampling_past = sampling_real && dss > th.sigma_threshold;
      const bool past = ((real && same_side) || sampling_past) && rel_ok && dr > th.relative_threshold;
      const bool in_band = rel_ok && dr > th.clear_fraction * th.relative_threshold &&
                           ((sigma_ok && same_side && ds > th.clear_fraction * th.sigma_threshold) ||
                            dss > th.clear_fraction * th.sigma_threshold);
      if (dss > ds) s.deviation_sigma = sampling_sigma;  // the test that sees the change better

      // Beyond the relative threshold on one side since (mode clock).
      double& beyond = beyond_since_[i][q];
      const bool up = own(q) > 0.0;
      if (!(rel_ok && dr > th.relative_threshold)) {
        beyond = kNaN;
      } else if (std::isnan(beyond) || beyond_up_[i][q] != up) {
        beyond = now;
        beyond_up_[i][q] = up;
      }

      double& timer = below_since_[i][q];
      bool changed = false;
      if (!s.flagged) {
        if (!past) {
          s.pending = false;
          s.since = 0.0;
          timer = kNaN;
          continue;
        }
        // The hold asks the deviation to persist, not its significance: where
        // the estimate's covariance was wide (it follows a change with its
        // covariance boosted, or the joint information is rebuilt after one)
        // and the deviation stood past the relative threshold on this side
        // all along, the hold counts from then. A fit's window counts also
        // where the condition was already pending.
        const double start = std::min(now - span, std::isnan(beyond) ? now : beyond);
        if (!s.pending || start < timer) {
          s.pending = true;
          s.since = t - (now - start);
          timer = start;
        }
        if (now - timer >= th.hold_time - kTimeSlack) {
          s.flagged = true;
          s.pending = false;
          s.since = t;
          timer = kNaN;
          changed = true;
        }
      } else {
        if (in_band) {
          timer = kNaN;
          continue;
        }
        if (std::isnan(timer)) timer = now;
        if (now - timer >= th.clear_time - kTimeSlack) {
          s.flagged = false;
          s.since = 0.0;
          timer = kNaN;
          changed = true;
          g[2 * q] = g[2 * q + 1] = 0.0;
        }
      }
      if (changed) {
        FlagChange ch;
        ch.mode = static_cast<int>(i);
        ch.quantity = static_cast<Quantity>(q);
        ch.raised = s.flagged;
        ch.time = t;
        ch.value = x(q);
        ch.baseline = x0(q);
        ch.deviation_sigma = s.deviation_sigma;
        ch.deviation_relative = s.deviation_relative;
        ch.chi_square = m.chi_square;
        ch.cusum = s.cusum;
        changes.push_back(ch);
      }
    }
  }
  if (t_ok) last_t_ = t;
}

bool FaultDetector::any_flag() const {
  for (const ModeStatus& m : modes_)
    for (const QuantityStatus& s : m.quantity)
      if (s.flagged) return true;
  return false;
}

std::uint64_t FaultDetector::flag_bits() const {
  std::uint64_t bits = 0;
  for (std::size_t i = 0; i < modes_.size(); ++i)
    for (int q = 0; q < kQuantities; ++q)
      if (modes_[i].quantity[q].flagged) bits |= std::uint64_t{1} << (i * kQuantities + static_cast<std::size_t>(q));
  return bits;
}

}  // namespace modalwatch
