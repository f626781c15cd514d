#include "modalwatch/initial_modes.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <complex>
#include <limits>
#include <numbers>
#include <stdexcept>

#include <Eigen/QR>

#include "modalwatch/spectra.hpp"

namespace modalwatch {
namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;
// Welch averages of the default segment length, and the fewest that a finer
// resolution may leave (frequency_response).
constexpr Eigen::Index kAveragedSegments = 8;
constexpr Eigen::Index kFewestSegments = 4;

struct Peak {
  Eigen::Index bin = 0;
  double prominence = 0.0;  // |H| above the higher flanking minimum
};

// Frequency (Hz) where log|H| crosses `level` walking from the peak bin in
// direction `step`, linearly interpolated; negative when |H| rises above the
// peak or the band ends first (the half-power point is not resolved on that side).
double crossing(const Eigen::VectorXd& logh, const Eigen::VectorXd& f, Eigen::Index peak, int step, double level,
                Eigen::Index first, Eigen::Index last) {
  for (Eigen::Index k = peak + step; k >= first && k <= last; k += step) {
    if (logh(k) > logh(peak)) return -1.0;
    if (logh(k) <= level) {
      const Eigen::Index j = k - step;
      const double w = (logh(j) - level) / (logh(j) - logh(k));
      return f(j) + w * (f(k) - f(j));
    }
  }
  return -1.0;
}

// H = S_yu S_uu^-1 of several inputs at every frequency, from the Welch
// spectra of y with each input and of the inputs with each other.
void several_inputs(const Record& data, double T, int segment_length, FrequencyResponse& out) {
  const int m = data.inputs();
  std::vector<Spectra> yu;  // e = y, u = u_j: cross * input_psd = S_{y u_j}
  for (int j = 0; j < m; ++j) yu.push_back(welch_spectra(data.y, data.input(j), T, segment_length));
  const Eigen::Index F = yu[0].frequency_hz.size();
  // S_uu(i, j) = E[U_i conj(U_j)]; the diagonal from yu.
  std::vector<Eigen::MatrixXcd> suu(static_cast<std::size_t>(F), Eigen::MatrixXcd::Zero(m, m));
  for (int j = 0; j < m; ++j)
    for (Eigen::Index k = 0; k < F; ++k) suu[static_cast<std::size_t>(k)](j, j) = yu[j].input_psd(k);
  for (int i = 0; i < m; ++i)
    for (int j = i + 1; j < m; ++j) {
      const Spectra uij = welch_spectra(data.input(i), data.input(j), T, segment_length);
      for (Eigen::Index k = 0; k < F; ++k) {
        const std::complex<double> c = uij.cross(k) * uij.input_psd(k);
        suu[static_cast<std::size_t>(k)](i, j) = c;
        suu[static_cast<std::size_t>(k)](j, i) = std::conj(c);
      }
    }
  out.frequency_hz = yu[0].frequency_hz;
  out.segments = yu[0].segments;
  out.response.resize(F);
  out.further_responses.assign(static_cast<std::size_t>(m - 1), Eigen::VectorXcd(F));
  out.excitation = Eigen::VectorXd::Zero(F);
  out.coherence.resize(F);
  for (Eigen::Index k = 0; k < F; ++k) {
    Eigen::RowVectorXcd syu(m);
    for (int j = 0; j < m; ++j) syu(j) = yu[j].cross(k) * yu[j].input_psd(k);
    const Eigen::MatrixXcd& S = suu[static_cast<std::size_t>(k)];
    // A frequency no input excites (DC of zero-mean inputs) has no estimate.
    const Eigen::RowVectorXcd H =
        S.norm() > 0.0
            ? Eigen::RowVectorXcd(S.transpose().completeOrthogonalDecomposition().solve(syu.transpose()).transpose())
            : Eigen::RowVectorXcd(Eigen::RowVectorXcd::Zero(m));
    out.response(k) = H(0);
    for (int j = 1; j < m; ++j) out.further_responses[static_cast<std::size_t>(j - 1)](k) = H(j);
    out.excitation(k) = S.diagonal().real().sum();
    // Multiple coherence: the share of S_yy that the inputs explain, H S_uu H^H / S_yy.
    const double syy = yu[0].residual_psd(k);
    const double explained = (H * S * H.adjoint())(0, 0).real();
    out.coherence(k) = syy > 0.0 ? std::clamp(explained / syy, 0.0, 1.0) : 0.0;
  }
}

}  // namespace

double FrequencyResponse::magnitude(Eigen::Index k) const {
  if (further_responses.empty()) return std::abs(response(k));
  double sum = std::norm(response(k));
  for (const auto& h : further_responses) sum += std::norm(h(k));
  return std::sqrt(sum);
}

namespace {

FrequencyResponse estimate_at(const Record& data, bool closed_loop, int segment_length, Hold input) {
  const double T = data.sample_time();
  FrequencyResponse out;
  if (data.inputs() > 1) {
    several_inputs(data, T, segment_length, out);
  } else if (!closed_loop) {
    const Spectra s = welch_spectra(data.y, data.u, T, segment_length);
    out.frequency_hz = s.frequency_hz;
    out.response = s.cross;
    out.excitation = s.input_psd;
    out.coherence = s.coherence;
    out.segments = s.segments;
  } else {
    const Spectra yr = welch_spectra(data.y, data.r, T, segment_length);
    const Spectra ur = welch_spectra(data.u, data.r, T, segment_length);
    out.frequency_hz = yr.frequency_hz;
    out.response.resize(yr.cross.size());
    for (Eigen::Index k = 0; k < yr.cross.size(); ++k)
      out.response(k) = std::abs(ur.cross(k)) > 0.0 ? yr.cross(k) / ur.cross(k) : std::complex<double>(0.0);
    out.excitation = yr.input_psd;
    out.coherence = yr.coherence;
    out.segments = yr.segments;
  }
  // The zero-order hold delays by half a sample: H_d ~ G e^{-j w T / 2}.
  if (input == Hold::zoh)
    for (Eigen::Index k = 0; k < out.response.size(); ++k) {
      const std::complex<double> advance = std::polar(1.0, 0.5 * kTwoPi * out.frequency_hz(k) * T);
      out.response(k) *= advance;
      for (auto& h : out.further_responses) h(k) *= advance;
    }
  return out;
}

// A resonance and the bin of its peak, where each input's residue is read.
struct Resonance {
  ModalParameters modal;
  Eigen::Index bin = 0;
  bool narrow = false;  // its half-power bandwidth spans two bins or fewer
};

// The searched band: from the first to the last excited frequency, without
// DC; false when it has fewer than three bins.
bool excited_band(const FrequencyResponse& h, const PeakOptions& options, Eigen::Index& first, Eigen::Index& last) {
  const Eigen::Index F = h.frequency_hz.size();
  if (F < 4) return false;
  const double excited = options.excited_fraction * h.excitation.tail(F - 1).maxCoeff();
  first = last = -1;
  for (Eigen::Index k = 1; k < F; ++k)
    if (h.excitation(k) > excited) {
      if (first < 0) first = k;
      last = k;
    }
  if (first < 0) return false;
  // A coloured input that rolls off: the output follows it on, without a gap.
  while (first > 1 && h.coherence(first - 1) >= options.coherent) --first;
  while (last + 1 < F && h.coherence(last + 1) >= options.coherent) ++last;
  return last - first >= 2;
}

std::vector<Resonance> find_resonances(const FrequencyResponse& h, int count, const PeakOptions& options,
                                       int output_derivatives) {
  const Eigen::Index F = h.frequency_hz.size();
  std::vector<Resonance> out;
  Eigen::Index first = -1, last = -1;
  if (count <= 0 || !excited_band(h, options, first, last)) return out;
  Eigen::VectorXd logh(F);
  for (Eigen::Index k = 0; k < F; ++k) logh(k) = std::log(std::max(h.magnitude(k), 1e-300));

  std::vector<Peak> peaks;
  for (Eigen::Index k = first + 1; k < last; ++k) {
    if (!(logh(k) > logh(k - 1) && logh(k) >= logh(k + 1))) continue;
    // Topographic prominence: the lowest point on each side before the curve
    // rises above this peak (or the band ends); the higher of the two.
    double left = logh(k), right = logh(k);
    for (Eigen::Index j = k - 1; j >= first && logh(j) <= logh(k); --j) left = std::min(left, logh(j));
    for (Eigen::Index j = k + 1; j <= last && logh(j) <= logh(k); ++j) right = std::min(right, logh(j));
    const double relative = 1.0 - std::exp(std::max(left, right) - logh(k));  // of |H| at the peak
    // Relative standard deviation of |H1| with K averages: sqrt((1 - g) / (2 K g)), g the coherence.
    const double g = std::clamp(h.coherence(k), 1e-6, 1.0);
    const double noise = std::sqrt((1.0 - g) / (2.0 * std::max(1, h.segments) * g));
    if (relative < std::max(options.min_prominence, options.noise_sigmas * noise)) continue;
    // Ranked by the height the resonance adds to |H|: a ripple where |H| is
    // small (near Nyquist, between modes) rises little in absolute terms.
    peaks.push_back({k, relative * std::exp(logh(k))});
  }
  std::sort(peaks.begin(), peaks.end(), [](const Peak& a, const Peak& b) { return a.prominence > b.prominence; });
  if (!peaks.empty()) {
    const double floor = options.min_share * peaks.front().prominence;
    peaks.erase(std::remove_if(peaks.begin(), peaks.end(), [&](const Peak& p) { return p.prominence < floor; }),
                peaks.end());
  }
  if (static_cast<int>(peaks.size()) > count) peaks.resize(static_cast<std::size_t>(count));

  const double df = h.frequency_hz(1) - h.frequency_hz(0);
  for (const Peak& p : peaks) {
    const Eigen::Index k = p.bin;
    // Parabolic interpolation of log|H| through the three bins at the peak.
    const double c = 0.5 * (logh(k - 1) - logh(k + 1)) / (logh(k - 1) - 2.0 * logh(k) + logh(k + 1));
    const double f0 = h.frequency_hz(k) + std::clamp(c, -0.5, 0.5) * df;
    const double level = logh(k) - 0.5 * std::log(2.0);  // half power
    const double lo = crossing(logh, h.frequency_hz, k, -1, level, first, last);
    const double hi = crossing(logh, h.frequency_hz, k, +1, level, first, last);
    double width = -1.0;  // half-power bandwidth, Hz
    if (lo > 0.0 && hi > 0.0)
      width = hi - lo;
    else if (lo > 0.0)
      width = 2.0 * (f0 - lo);
    else if (hi > 0.0)
      width = 2.0 * (hi - f0);
    ModalParameters m;
    m.wn = kTwoPi * f0;
    // A bandwidth under two bins is the Hann window's, not the mode's: the
    // mode's is narrower still, zeta < df / f0, and it starts at half that
    // bound when the default lies above it.
    const bool narrow = width > 0.0 && width <= 2.0 * df;
    m.zeta = width > 2.0 * df ? width / (2.0 * f0)
             : narrow         ? std::min(options.default_zeta, 0.5 * df / f0)
                              : options.default_zeta;
    m.gain = resonance_gain(h.response(k), m.wn, m.zeta, output_derivatives);
    out.push_back({m, k, narrow});
  }
  std::sort(out.begin(), out.end(), [](const Resonance& a, const Resonance& b) { return a.modal.wn < b.modal.wn; });
  return out;
}

// Welch segments that overlap by half: 2 N / L - 1 of length L.
Eigen::Index segments_of(Eigen::Index N, int segment_length) { return 2 * N / segment_length - 1; }

// The longest power of two, at least 64, that still gives kAveragedSegments.
int default_segment_length(Eigen::Index N) {
  int length = 64;
  while (segments_of(N, 2 * length) >= kAveragedSegments) length *= 2;
  return length;
}

}  // namespace

FrequencyResponse frequency_response(const Record& data, bool closed_loop, int segment_length, Hold input) {
  if (closed_loop && !data.has_reference())
    throw std::invalid_argument("frequency_response: closed loop needs the reference r in the record");
  if (closed_loop && data.inputs() > 1)
    throw std::invalid_argument("frequency_response: a closed loop has one input (the controller's u)");
  if (segment_length <= 0) segment_length = default_segment_length(data.size());
  return estimate_at(data, closed_loop, segment_length, input);
}

FrequencyResponse resolving_response(const Record& data, bool closed_loop, Hold input) {
  const Eigen::Index N = data.size();
  int length = default_segment_length(N);
  FrequencyResponse h = frequency_response(data, closed_loop, length, input);
  // A resonance narrower than two bins is the window's width, not the mode's,
  // and its leakage lowers the coherence that the peak test trusts: a lightly
  // damped mode can fail that test only because the bins are too wide.
  // Finer bins, as long as enough segments remain to average and the fewer
  // averages do not hide a resonance that the wider bins show.
  constexpr int kAll = std::numeric_limits<int>::max();
  std::vector<Resonance> peaks = find_resonances(h, kAll, PeakOptions{}, 0);
  while (segments_of(N, 2 * length) >= kFewestSegments &&
         std::any_of(peaks.begin(), peaks.end(), [](const Resonance& r) { return r.narrow; })) {
    FrequencyResponse finer = frequency_response(data, closed_loop, 2 * length, input);
    std::vector<Resonance> finer_peaks = find_resonances(finer, kAll, PeakOptions{}, 0);
    if (finer_peaks.size() < peaks.size()) break;
    length *= 2;
    h = std::move(finer);
    peaks = std::move(finer_peaks);
  }
  return h;
}

double resonance_gain(std::complex<double> h, double wn, double zeta, int output_derivatives) {
  // The peak of (j w)^z b0 / (p^2/wn^2 + ...) at wn: the position's h / (j wn)^z.
  const std::complex<double> position =
      output_derivatives == 0 ? h : h / std::pow(std::complex<double>(0.0, wn), output_derivatives);
  const double gain = -2.0 * zeta * position.imag();
  return gain != 0.0 ? gain : 2.0 * zeta * std::abs(position);
}

std::vector<ModalParameters> resonance_peaks(const FrequencyResponse& h, int count, const PeakOptions& options,
                                             int output_derivatives) {
  std::vector<ModalParameters> out;
  for (const Resonance& r : find_resonances(h, count, options, output_derivatives)) out.push_back(r.modal);
  return out;
}

AdditiveModel initial_modes(const Record& data, int count, bool closed_loop, const PeakOptions& options,
                            int output_derivatives) {
  return initial_modes(resolving_response(data, closed_loop), count, options, {}, output_derivatives);
}

AdditiveModel initial_modes(const FrequencyResponse& h, int count, const PeakOptions& options,
                            const std::vector<std::string>& inputs, int output_derivatives) {
  const std::vector<Resonance> peaks = find_resonances(h, count, options, output_derivatives);
  AdditiveModel model;
  const int m = h.inputs();
  if (m == 1) {
    for (std::size_t i = 0; i < peaks.size(); ++i)
      model.submodels.push_back(make_mode("mode" + std::to_string(i + 1), peaks[i].modal, output_derivatives));
    return model;
  }
  for (int j = 0; j < m; ++j)
    model.inputs.push_back(j < static_cast<int>(inputs.size()) ? inputs[static_cast<std::size_t>(j)]
                                                               : "u" + std::to_string(j + 1));
  for (std::size_t i = 0; i < peaks.size(); ++i)
    for (int j = 0; j < m; ++j) {
      ModalParameters p = peaks[i].modal;
      p.gain = resonance_gain(h.input_response(j)(peaks[i].bin), p.wn, p.zeta, output_derivatives);
      model.submodels.push_back(
          make_mode("mode" + std::to_string(i + 1) + "_" + model.input_name(j), p, output_derivatives));
      model.submodels.back().input = j;
      // One resonance, one pole pair: every input's submodel shares the first's A.
      if (j > 0) model.submodels.back().poles_of = model.submodels[model.submodels.size() - 1 - j].name;
    }
  return model;
}

std::vector<NonResonantStart> non_resonant_starts(const FrequencyResponse& h, const PeakOptions& options,
                                                  int output_derivatives) {
  std::vector<NonResonantStart> out;
  Eigen::Index first = -1, last = -1;
  if (h.inputs() != 1 || !excited_band(h, options, first, last)) return out;
  const int z = output_derivatives;
  using C = std::complex<double>;
  // The real b0 of least relative error sum gamma^2 |H - b0 g|^2 / (|H|^2 f)
  // (the squared coherence gamma^2 discounts the bins where noise makes H; 1/f
  // weighs each decade alike, as a Bode plot reads, where the bins crowd the
  // top decade), and that error relative to sum gamma^2 / f.
  Eigen::VectorXd weight(last - first + 1);
  double total = 0.0;
  for (Eigen::Index k = first; k <= last; ++k) {
    const double per_decade = std::clamp(h.coherence(k), 0.0, 1.0) / h.frequency_hz(k);
    weight(k - first) = per_decade / std::max(std::norm(h.response(k)), 1e-300);
    total += per_decade;
  }
  auto fit = [&](auto&& g, double& b0) {
    double gh = 0.0, gg = 0.0;
    for (Eigen::Index k = first; k <= last; ++k) {
      const C gk = g(kTwoPi * h.frequency_hz(k));
      gh += weight(k - first) * (std::conj(gk) * h.response(k)).real();
      gg += weight(k - first) * std::norm(gk);
    }
    b0 = gg > 0.0 ? gh / gg : 0.0;
    double e = 0.0;
    for (Eigen::Index k = first; k <= last; ++k)
      e += weight(k - first) * std::norm(h.response(k) - b0 * g(kTwoPi * h.frequency_hz(k)));
    return total > 0.0 ? e / total : std::numeric_limits<double>::infinity();
  };
  // The best of each structure.
  auto consider = [&](double e, Submodel s, std::string what) {
    if (!std::isfinite(e) || !(s.b(0) != 0.0)) return;
    auto same = std::find_if(out.begin(), out.end(), [&](const NonResonantStart& o) { return o.structure == what; });
    if (same == out.end())
      same = out.insert(out.end(), NonResonantStart{});
    else if (!(std::sqrt(e) < same->relative_error))
      return;
    same->submodel = std::move(s);
    same->structure = std::move(what);
    same->relative_error = std::sqrt(e);
    same->band_hz = {h.frequency_hz(first), h.frequency_hz(last)};
  };
  double b0 = 0.0;
  if (z == 0) {
    const double e = fit([](double) { return C(1.0); }, b0);  // before b0 is read
    consider(e, make_rigid_body("direct", b0, 0), "a feedthrough b0");
  }
  for (const int l : {1, 2}) {
    const double e = fit([&](double w) { return std::pow(C(0.0, w), z - l); }, b0);
    consider(e, make_rigid_body("rigid", b0, l, z), l == 1 ? "a rigid body b0/p" : "a rigid body b0/p^2");
  }
  // A lag of one pole, or of two real (or critically damped) poles, its
  // corner on a grid from a decade below the band to a decade above it.
  const double w_lo = 0.1 * kTwoPi * h.frequency_hz(first), w_hi = 10.0 * kTwoPi * h.frequency_hz(last);
  constexpr int kGrid = 121;
  // The lag of one pole is measured as b0 / (1 + p / wc) whatever the sensor
  // (l = z rigid poles): a position lag, a motor's speed (b0 / (p (1 + p / wc))
  // read as velocity), a mass behind an actuator's lag read as acceleration.
  // A rigid body behind a lag (l = 1): a positioning axis, a mass with viscous
  // friction, b0 / (p (1 + p / wc)) in position (read as velocity it is the lag).
  const std::array<int, 2> rigid_poles = {z, 1};
  for (std::size_t j = 0; j < (z == 1 ? 1u : 2u); ++j) {
    const int l = rigid_poles[j];
    for (int i = 0; i < kGrid; ++i) {
      const double wc = w_lo * std::pow(w_hi / w_lo, static_cast<double>(i) / (kGrid - 1));
      const double e =
          fit([&](double w) { return (l == z ? C(1.0) : std::pow(C(0.0, w), z - l)) / C(1.0, w / wc); }, b0);
      Submodel lag;
      lag.name = l == z ? "lag" : "rigid";
      lag.n = 1;
      lag.m = 0;
      lag.rigid_poles = l;
      lag.output_derivatives = z;
      lag.a = Eigen::VectorXd::Constant(1, 1.0 / wc);
      lag.b = Eigen::VectorXd::Constant(1, b0);
      consider(e, std::move(lag), l == z ? "a lag of one pole" : "a rigid body with a lag b0/(p (1 + p/wc))");
    }
  }
  for (const double zeta : {0.7, 1.0, 2.0, 5.0})
    for (int i = 0; i < kGrid; ++i) {
      const double wn = w_lo * std::pow(w_hi / w_lo, static_cast<double>(i) / (kGrid - 1));
      const double e =
          fit([&](double w) { return std::pow(C(0.0, w), z) / C(1.0 - w * w / (wn * wn), 2.0 * zeta * w / wn); }, b0);
      consider(e, make_mode("mode1", {wn, zeta, b0}, z), "a lag of two poles (zeta >= 0.7)");
    }
  std::stable_sort(out.begin(), out.end(), [](const NonResonantStart& a, const NonResonantStart& b) {
    return a.relative_error < b.relative_error;
  });
  return out;
}

NonResonantStart non_resonant_start(const FrequencyResponse& h, const PeakOptions& options, int output_derivatives) {
  std::vector<NonResonantStart> starts = non_resonant_starts(h, options, output_derivatives);
  return starts.empty() ? NonResonantStart{} : std::move(starts.front());
}

}  // namespace modalwatch
