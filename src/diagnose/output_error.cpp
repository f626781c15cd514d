// The output-error refinement of diagnose (output_error.hpp).
#include "output_error.hpp"

#include <cmath>
#include <exception>
#include <vector>

#include <Eigen/Cholesky>
#include <Eigen/QR>

namespace modalwatch::diagnose_detail {

// ------------------------------------------------------------ parameters

Eigen::VectorXd pack(const AugmentedModel& m) {
  const ModelEffects& e = m.effects;
  std::vector<double> extra;
  if (e.output_offset_on) extra.push_back(e.output_offset);
  if (e.input_offset_on) extra.push_back(e.input_offset);
  if (e.drift_on) extra.push_back(e.drift);
  if (e.coulomb_on) extra.push_back(e.coulomb);
  if (e.cubic_on) extra.push_back(e.cubic);
  const Eigen::VectorXd beta = free_beta(m.linear);
  const int nb = static_cast<int>(beta.size());
  Eigen::VectorXd p(nb + static_cast<int>(extra.size()));
  p.head(nb) = beta;
  for (std::size_t i = 0; i < extra.size(); ++i) p(nb + static_cast<int>(i)) = extra[i];
  return p;
}

void unpack(const Eigen::VectorXd& p, AugmentedModel& m) {
  ModelEffects& e = m.effects;
  // The effects that are on take the last entries; the linear part the rest.
  const int on = int(e.output_offset_on) + int(e.input_offset_on) + int(e.drift_on) + int(e.coulomb_on) + int(e.cubic_on);
  const int nb = static_cast<int>(p.size()) - on;
  set_free_beta(m.linear, p.head(nb));
  int i = nb;
  if (e.output_offset_on) e.output_offset = p(i++);
  if (e.input_offset_on) e.input_offset = p(i++);
  if (e.drift_on) e.drift = p(i++);
  if (e.coulomb_on) e.coulomb = p(i++);
  if (e.cubic_on) e.cubic = p(i++);
}

// ------------------------------------------------------------ output error

Eigen::VectorXd output(const AugmentedModel& m, const Problem& pb) {
  if (pb.simulations) ++*pb.simulations;
  try {
    Eigen::VectorXd y = simulate_augmented(m, pb.data, pb.loop);
    if (!y.allFinite()) return {};
    return y;
  } catch (const std::exception&) {
    return {};
  }
}

double cost_of(const Eigen::VectorXd& y_hat, const Eigen::VectorXd& y) {
  if (y_hat.size() != y.size()) return kInf;
  const double c = (y - y_hat).squaredNorm();
  return std::isfinite(c) ? c : kInf;
}

Refined refine(const AugmentedModel& start, const Problem& pb, int iterations, bool with_covariance) {
  Refined best{start, kInf, {}};
  const Eigen::VectorXd p0 = pack(start);
  const int P = static_cast<int>(p0.size());
  Eigen::VectorXd scale(P);
  const double typical = p0.size() ? p0.cwiseAbs().maxCoeff() : 1.0;
  for (int j = 0; j < P; ++j) scale(j) = p0(j) != 0.0 ? std::abs(p0(j)) : 1e-6 * std::max(typical, 1e-12);
  auto model_at = [&](const Eigen::VectorXd& delta) {
    AugmentedModel m = start;
    unpack(p0 + scale.cwiseProduct(delta), m);
    return m;
  };
  Eigen::VectorXd delta = Eigen::VectorXd::Zero(P);
  Eigen::VectorXd y_hat = output(start, pb);
  double cost = cost_of(y_hat, pb.data.y);
  if (!std::isfinite(cost)) return best;
  best.cost = cost;
  double lambda = 1e-3;
  const double h = 1e-6;
  Eigen::MatrixXd J(pb.data.size(), P);
  auto jacobian = [&] {
    for (int j = 0; j < P; ++j) {
      Eigen::VectorXd d = delta;
      d(j) += h;
      const Eigen::VectorXd yj = output(model_at(d), pb);
      J.col(j) = yj.size() == y_hat.size() ? Eigen::VectorXd((yj - y_hat) / h) : Eigen::VectorXd::Zero(y_hat.size());
    }
  };
  for (int it = 0; it < iterations && P > 0; ++it) {
    jacobian();
    const Eigen::VectorXd r = pb.data.y - y_hat;
    const Eigen::MatrixXd A = J.transpose() * J;
    const Eigen::VectorXd g = J.transpose() * r;
    bool accepted = false;
    for (int tries = 0; tries < 12; ++tries) {
      Eigen::MatrixXd M = A;
      for (int j = 0; j < P; ++j) M(j, j) += lambda * std::max(A(j, j), 1e-12);
      const Eigen::VectorXd step = M.ldlt().solve(g);
      if (!step.allFinite()) {
        lambda *= 4.0;
        continue;
      }
      const Eigen::VectorXd trial = delta + step;
      const Eigen::VectorXd y_trial = output(model_at(trial), pb);
      const double c = cost_of(y_trial, pb.data.y);
      if (c < cost) {
        const double drop = (cost - c) / cost;
        delta = trial;
        y_hat = y_trial;
        cost = c;
        lambda = std::max(lambda / 3.0, 1e-9);
        accepted = true;
        if (drop < 1e-10) it = iterations;  // converged
        break;
      }
      lambda *= 4.0;
    }
    if (!accepted) break;
  }
  best.model = model_at(delta);
  best.cost = cost;
  const Eigen::Index N = pb.data.size();
  if (with_covariance && iterations == 0 && P > 0 && N > P) {
    jacobian();
    const Eigen::MatrixXd Js = J * scale.cwiseInverse().asDiagonal();  // d y / d p
    const Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod(Js.transpose() * Js);
    best.covariance = cost / static_cast<double>(N - P) * cod.pseudoInverse();
  }
  return best;
}

}  // namespace modalwatch::diagnose_detail
