#include "modalwatch/physical.hpp"

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdio>
#include <limits>
#include <numbers>

#include "modalwatch/polynomial.hpp"

namespace modalwatch {
namespace {

std::string format(const char* fmt, double a, double b = 0.0, double c = 0.0) {
  char buf[160];
  std::snprintf(buf, sizeof buf, fmt, a, b, c);
  return buf;
}

// Whether a mode's shape D(jw) = 1/A(jw) - 1, its departure from the constant
// b0 relative to b0, stays within `sigmas` standard deviations of itself at
// every w of the band [0, w_max], with the covariance of (a_1, a_2) by
// first-order propagation (dD/da_k = -(jw)^k / A^2). Relative to b0, so that a
// gain the record leaves open (a direction shared with another submodel) does
// not make a resolved resonance look like a constant. `worst` gets the largest
// |D| / std(D).
bool constant_on_band(const Submodel& s, const Eigen::Matrix2d& a_covariance, double w_max, double sigmas,
                      double& worst) {
  const int points = 2000;  // fine enough for the peak: its half-power width is 2 zeta wn
  worst = 0.0;
  for (int k = 1; k <= points; ++k) {
    const double w = w_max * k / points;
    const std::complex<double> p(0.0, w);
    const std::complex<double> A = 1.0 + s.a(0) * p + s.a(1) * p * p;
    const std::complex<double> D = 1.0 / A - 1.0;
    const std::complex<double> g1 = -p / (A * A), g2 = -p * p / (A * A);
    const Eigen::Vector2d re(g1.real(), g2.real()), im(g1.imag(), g2.imag());
    const double var = re.dot(a_covariance * re) + im.dot(a_covariance * im);
    const double ratio = var > 0.0 ? std::abs(D) / std::sqrt(var) : std::numeric_limits<double>::infinity();
    worst = std::max(worst, ratio);
    if (!(ratio <= sigmas)) return false;
  }
  return true;
}

}  // namespace

const char* verdict_name(ModeVerdict verdict) {
  switch (verdict) {
    case ModeVerdict::physical:
      return "physical";
    case ModeVerdict::feedthrough:
      return "feedthrough";
    case ModeVerdict::unstable:
      return "unstable";
    case ModeVerdict::merged:
      return "merged";
    case ModeVerdict::removed:
      return "removed";
  }
  return "?";
}

bool PhysicalCheck::changed() const {
  return std::any_of(findings.begin(), findings.end(),
                     [](const ModeFinding& f) { return f.verdict != ModeVerdict::physical; });
}

namespace {

int index_of(const std::vector<Submodel>& subs, const std::string& name) {
  for (std::size_t i = 0; i < subs.size(); ++i)
    if (subs[i].name == name) return static_cast<int>(i);
  return -1;
}

// The submodel whose poles submodel i shares (i itself when it has its own).
int leader_of(const std::vector<Submodel>& subs, int i) {
  const int lead = subs[i].poles_of.empty() ? i : index_of(subs, subs[i].poles_of);
  return lead < 0 ? i : lead;
}

// Submodel j was merged into i: the other inputs' views of j's resonance go
// with it, each into i's view on its input (their gains add) or, where i's
// resonance has none there, into i's group.
void absorb_views(int j, int i, std::vector<Submodel>& subs, std::vector<bool>& removed,
                  std::vector<ModeFinding>& findings) {
  const int K = static_cast<int>(subs.size());
  const int lead_j = leader_of(subs, j), lead_i = leader_of(subs, i);
  if (lead_j == lead_i) return;
  const std::string from = subs[lead_j].name, into = subs[lead_i].name;
  for (int k = 0; k < K; ++k) {
    if (removed[k] || !(k == lead_j || subs[k].poles_of == from)) continue;
    int view = -1;
    for (int w = 0; w < K; ++w)
      if (!removed[w] && (w == lead_i || subs[w].poles_of == into) && subs[w].input == subs[k].input) view = w;
    if (view < 0) {
      subs[k].poles_of = into;
      continue;
    }
    const ModalParameters p = modal_parameters(subs[k]);
    subs[view].b(0) += subs[k].b(0);
    removed[k] = true;
    findings[k].verdict = ModeVerdict::merged;
    findings[k].into = subs[view].name;
    findings[k].reason = format("%.5g Hz (gain %.4g): another input's view of ", p.hz(), p.gain) + subs[j].name +
                         ", merged with it into " + subs[view].name;
  }
}

}  // namespace

PhysicalCheck check_physical(const AdditiveModel& fitted, const Eigen::MatrixXd& beta_covariance, double sample_time,
                             const PhysicalOptions& options) {
  const int K = static_cast<int>(fitted.submodels.size());
  const bool have_covariance = beta_covariance.rows() == fitted.n_beta() && beta_covariance.cols() == fitted.n_beta();
  const double nyquist = std::numbers::pi / sample_time;  // rad/s

  PhysicalCheck out;
  out.model.inputs = fitted.inputs;
  std::vector<Submodel> subs = fitted.submodels;
  std::vector<bool> removed(K, false);
  for (int i = 0; i < K; ++i) {
    const Submodel& s = fitted.submodels[i];
    ModeFinding f;
    f.submodel = s.name;
    f.fitted = modal_parameters(s);
    if (have_covariance) {
      const int o = fitted.offset(i), n = s.n_theta();
      f.fitted_std = modal_std(s, beta_covariance.block(o, o, n, n));
    }
    out.findings.push_back(f);
  }

  // Stability: the estimator's projection, reported.
  for (int i = 0; i < K; ++i) {
    Submodel& s = subs[i];
    if (s.n == 0 || is_hurwitz(s.a)) continue;
    ModeFinding& f = out.findings[i];
    const Eigen::VectorXd before = s.a;
    if (!project_stable(s.a)) continue;  // a_n = 0 or not finite: nothing to reflect
    f.verdict = ModeVerdict::unstable;
    f.reason = s.is_mode() ? format("a_1 = %.4g, a_2 = %.4g: unstable; projected to stability, now zeta = %.3g",
                                    before(0), before(1), modal_parameters(s).zeta)
                           : std::string("roots of A in the right half plane: reflected into the left half plane");
  }

  // Measured as a derivative (velocity, acceleration), a mode above Nyquist is
  // b0 p^z on the band: no constant, nor a resonance the samples show. It is
  // left out (while another submodel remains) and the model refitted.
  for (int i = 0; i < K; ++i) {
    const Submodel& s = subs[i];
    if (!s.is_mode() || s.output_derivatives == 0 || removed[i]) continue;
    const ModalParameters p = modal_parameters(s);
    if (p.wn < nyquist || std::count(removed.begin(), removed.end(), false) <= 1) continue;
    removed[i] = true;
    ModeFinding& f = out.findings[i];
    f.verdict = ModeVerdict::removed;
    f.reason = (f.reason.empty() ? "" : f.reason + "; then ") +
               format("%.4g Hz is above the Nyquist frequency %.4g Hz", p.hz(), nyquist / (2.0 * std::numbers::pi)) +
               " and, measured as " + output_kind_name(s.output_derivatives) +
               ", acts on the band as b0 p^z: no resonance of the record; left out and refitted";
    out.refit = true;
  }
  // Feedthrough: a position sensor's mode above Nyquist, or a constant on the
  // band within its uncertainty.
  for (int i = 0; i < K; ++i) {
    Submodel& s = subs[i];
    if (!s.is_mode() || s.output_derivatives != 0) continue;
    ModeFinding& f = out.findings[i];
    const ModalParameters p = modal_parameters(s);
    std::string why;
    double worst = 0.0;
    if (!(p.wn < nyquist))
      why = format("%.4g Hz is above the Nyquist frequency %.4g Hz", p.hz(), nyquist / (2.0 * std::numbers::pi));
    else if (have_covariance) {
      const int o = fitted.offset(i);
      if (constant_on_band(s, beta_covariance.block<2, 2>(o, o), nyquist, options.band_sigmas, worst))
        why = format("its response departs from the constant b0 by at most %.3g std over the band (0..%.4g Hz)", worst,
                     nyquist / (2.0 * std::numbers::pi));
    }
    if (why.empty()) continue;
    f.verdict = ModeVerdict::feedthrough;  // after a projection too: the reasons add up
    f.reason =
        (f.reason.empty() ? "" : f.reason + "; then ") + why + format(": replaced by the feedthrough %.6g", s.b(0));
    const int input = s.input;
    s = make_rigid_body(s.name, s.b(0), 0);
    s.input = input;
    out.refit = true;
  }

  // Merges: modes closer than their joint uncertainty with opposite-sign gains
  // whose resonances overlap, the closest pair (in joint standard deviations)
  // first. Two resonances cancel only where their peaks share a band: apart
  // by more than their half-power half-widths (zeta wn each), the sum keeps
  // both peaks whatever the uncertainty of a poorly excited one's frequency.
  for (;;) {
    int best_i = -1, best_j = -1;
    double best_score = options.merge_sigmas;
    for (int i = 0; i < K; ++i) {
      if (removed[i] || !subs[i].is_mode()) continue;
      for (int j = i + 1; j < K; ++j) {
        // Two inputs' views of one resonance are two submodels, never a pair to merge.
        if (removed[j] || !subs[j].is_mode() || subs[j].input != subs[i].input) continue;
        const ModalParameters pi = modal_parameters(subs[i]), pj = modal_parameters(subs[j]);
        if (!(pi.gain * pj.gain < 0.0)) continue;
        const double si = out.findings[i].fitted_std.wn, sj = out.findings[j].fitted_std.wn;
        const double joint = std::sqrt(si * si + sj * sj);
        const double gap = std::abs(pi.wn - pj.wn);
        if (!(gap <= std::abs(pi.zeta) * pi.wn + std::abs(pj.zeta) * pj.wn)) continue;
        const double score = joint > 0.0 ? gap / joint : (gap == 0.0 ? 0.0 : options.merge_sigmas + 1.0);
        if (score <= best_score) {
          best_score = score;
          best_i = i;
          best_j = j;
        }
      }
    }
    if (best_i < 0) break;
    const ModalParameters pi = modal_parameters(subs[best_i]), pj = modal_parameters(subs[best_j]);
    // One resonance: the mean frequency and damping, and the net gain; when the
    // two cancel completely the larger gain starts the refit (a zero gain leaves
    // the block's instruments without its poles).
    ModalParameters merged{0.5 * (pi.wn + pj.wn), 0.5 * (pi.zeta + pj.zeta), pi.gain + pj.gain};
    const double larger = std::abs(pi.gain) > std::abs(pj.gain) ? pi.gain : pj.gain;
    if (std::abs(merged.gain) < 1e-3 * std::abs(larger)) merged.gain = larger;
    const int input = subs[best_i].input;
    const std::string poles_of = subs[best_i].poles_of;
    subs[best_i] = make_mode(subs[best_i].name, merged, subs[best_i].output_derivatives);
    subs[best_i].input = input;
    subs[best_i].poles_of = poles_of;
    removed[best_j] = true;
    absorb_views(best_j, best_i, subs, removed, out.findings);
    ModeFinding& f = out.findings[best_j];
    f.verdict = ModeVerdict::merged;
    f.into = subs[best_i].name;
    f.reason = format("%.5g Hz (gain %.4g) is within %.2g joint std of", pj.hz(), pj.gain, best_score) + " " +
               subs[best_i].name +
               format(
                   " at %.5g Hz (gain %.4g) and within their half-power bandwidths: one resonance, merged and "
                   "refitted",
                   pi.hz(), pi.gain);
    out.refit = true;
  }

  // A feedthrough has no poles to share: a view of one keeps its own.
  for (int i = 0; i < K; ++i)
    if (!removed[i] && !subs[i].poles_of.empty() && !subs[leader_of(subs, i)].is_mode()) subs[i].poles_of.clear();
  for (int i = 0; i < K; ++i)
    if (!removed[i]) out.model.submodels.push_back(subs[i]);
  return out;
}

AdditiveModel physical_start(const AdditiveModel& start, double sample_time, std::vector<ModeFinding>& findings) {
  PhysicalCheck check = check_physical(start, Eigen::MatrixXd(), sample_time);
  for (ModeFinding& f : check.findings) {
    if (f.verdict == ModeVerdict::physical) continue;
    f.reason = "its start: " + f.reason;
    findings.push_back(f);
  }
  return check.changed() ? check.model : start;
}

FitResult fit_physical(const Record& data, const AdditiveModel& initial, const SrivcOptions& options,
                       std::vector<ModeFinding>& findings, const PhysicalOptions& physical) {
  FitResult result = fit_srivc(data, physical_start(initial, data.sample_time(), findings), options);
  // Each refit follows a change of structure that removes a mode or its poles,
  // so the rounds end within the number of submodels.
  for (std::size_t round = 0; round <= initial.submodels.size(); ++round) {
    const PhysicalCheck check = check_physical(result.model, result.covariance, data.sample_time(), physical);
    for (const auto& f : check.findings)
      if (f.verdict != ModeVerdict::physical) findings.push_back(f);
    if (!check.refit) {
      result.model = check.model;  // projected in place: same parameters, same covariance layout
      break;
    }
    result = fit_srivc(data, check.model, options);
  }
  return result;
}

}  // namespace modalwatch
