#include "modalwatch/effects.hpp"

namespace modalwatch {

EffectState::EffectState(const PlantEffects& e)
    : e_(e), u_past_(static_cast<std::size_t>(e.input_delay > 0 ? e.input_delay : 0), 0.0) {}

double EffectState::branches(double y_now) const {
  double b = e_.input_offset;
  if (e_.coulomb != 0.0) {
    const double v_sign = (y_now > y_prev_) ? 1.0 : ((y_now < y_prev_) ? -1.0 : 0.0);
    b -= e_.coulomb * v_sign;
  }
  if (e_.cubic != 0.0) {
    const double y_mid = 1.5 * y_now - 0.5 * y_prev_;  // middle of the hold interval
    b -= e_.cubic * y_mid * y_mid * y_mid;
  }
  return b;
}

void EffectState::end_sample(double u, double y_now) {
  if (!u_past_.empty()) {
    u_past_[head_] = u;
    head_ = (head_ + 1) % u_past_.size();
  }
  y_prev_ = y_now;
}

}  // namespace modalwatch
