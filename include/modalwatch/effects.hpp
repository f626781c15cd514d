#pragma once
// Effects a model of modes alone does not describe, around the additive model
// of eq. (5): `simulate` makes records that carry them and `diagnose` fits them.
// The plant input and the output are
//
//   u_p(t_k) = u(t_{k-d}) + u_off - Fc sign(y_k - y_{k-1}) - c y_m^3   (held over [t_k, t_k+1))
//   y_m      = 1.5 y_k - 0.5 y_{k-1}
//   y(t_k)   = p^z sum_i G_i(p) u_p + y_off + drift (t_k - t_0)
//
// with y_k the noise-free position response of the submodels, sum_i B_i/(p^l_i A_i) u_p,
// at t_k before the input sample acts: the output itself for a position sensor
// and strictly proper submodels, without the feedthrough for a biproper one.
// With a velocity or acceleration sensor (Submodel::output_derivatives) y_k is
// still that position, from the same filter states as the measured output
// p^z sum_i G_i u_p: the cubic stiffness acts on the structure's displacement
// and the Coulomb friction on the sign of its velocity, while the offset and
// the drift stay on the measured output. The nonlinear branches (Coulomb, cubic) are
// thereby sampled and held like the input, and the loop through them stays
// explicit without an extra sample of delay. The cubic branch takes y
// extrapolated to the middle of the hold interval: held at y_k its stiffness
// would lag by half an interval, which acts as negative damping (felt at
// w T ~ 0.7).
#include <cstddef>
#include <vector>

namespace modalwatch {

// The effects' parameters; zero is "absent".
struct PlantEffects {
  double output_offset = 0.0;  // y_off, y units (sensor offset)
  double input_offset = 0.0;   // u_off, u units (force offset)
  double drift = 0.0;          // y units per s, from the first sample
  int input_delay = 0;         // d, samples
  double coulomb = 0.0;        // Fc >= 0, u units
  double cubic = 0.0;          // c, u units per position unit cubed (y units s^z; > 0: hardening)
  // The branches that feed the plant output back into its input.
  bool feeds_back() const { return coulomb != 0.0 || cubic != 0.0; }
  bool operator==(const PlantEffects&) const = default;
};

// The effects in a simulation loop: the inputs waiting out the delay and the
// previous output. Per sample k, with y_now the submodels' output at t_k before
// u_k acts:
//   u_p = delayed(u_k) + branches(y_now)     over [t_k, t_k+1)
//   y_k = (submodels' output) + output_terms(t_k - t_0)
//   end_sample(u_k, y_now)
// A loop that integrates in substeps re-evaluates branches() at the start of
// each substep and calls end_substep() after it.
class EffectState {
 public:
  explicit EffectState(const PlantEffects& e);

  // The plant input besides u: u_off minus the Coulomb and cubic branches.
  double branches(double y_now) const;
  // u_{k-d}: u itself without a delay, 0 before the first d samples.
  double delayed(double u) const { return e_.input_delay == 0 ? u : u_past_[head_]; }
  bool delays() const { return e_.input_delay > 0; }
  // The plant input fixed before u_k is known: the branches, plus u_{k-d} when
  // delayed. Through the submodels' feedthrough it is part of y_k, which a
  // closed loop needs before it computes u_k.
  double known_input(double branches) const { return branches + (delays() ? u_past_[head_] : 0.0); }
  // y_off + drift (t_k - t_0).
  double output_terms(double since_start) const {
    return e_.drift == 0.0 ? e_.output_offset : e_.output_offset + e_.drift * since_start;
  }

  void end_sample(double u, double y_now);
  void end_substep(double y_now) { y_prev_ = y_now; }

 private:
  PlantEffects e_;
  std::vector<double> u_past_;  // ring of the last d inputs, oldest at head_
  std::size_t head_ = 0;
  double y_prev_ = 0.0;  // y_now one (sub)step back
};

}  // namespace modalwatch
