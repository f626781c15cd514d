#pragma once
// Shared by bench_estimator and step_driver: the seed paper's plant (K = 3) or
// its first two modes (K = 2), simulated once, and an estimator built as
// `modalwatch track` builds it, fed from the record in an endless loop.
#include <cstdint>
#include <string>

#include "modalwatch/estimator.hpp"
#include "modalwatch/io/config.hpp"
#include "modalwatch/simulator.hpp"

namespace modalwatch::bench {

inline const Config& paper_config() {
  static const Config config = load_config(std::string(MODALWATCH_SOURCE_DIR) + "/config/paper-sim.yaml");
  return config;
}

// The paper's model and plant restricted to the first K submodels.
inline Config paper_subset(int K) {
  Config c = paper_config();
  c.model.submodels.resize(static_cast<std::size_t>(K));
  c.submodel_settings.resize(static_cast<std::size_t>(K));
  c.plant->modes.resize(static_cast<std::size_t>(K));
  // load_config fills the estimator's per-submodel lists: one entry per submodel.
  c.estimator.forgetting.resize(static_cast<std::size_t>(K));
  for (auto* per_submodel : {&c.estimator.random_walks, &c.estimator.stabilisations, &c.estimator.min_memories})
    if (!per_submodel->empty()) per_submodel->resize(static_cast<std::size_t>(K));
  if (c.estimator.initial_covariance.size() > static_cast<std::size_t>(K))
    c.estimator.initial_covariance.resize(static_cast<std::size_t>(K));
  return c;
}

inline Record simulate_paper(int K, bool closed_loop, double duration) {
  const Config c = paper_subset(K);
  ExperimentSpec e = *c.experiment;
  e.closed_loop = closed_loop;  // open loop: the reference signal drives the plant directly
  e.duration = duration;
  return simulate(*c.plant, e).record;
}

// Feeds a record to an estimator forever: after the last sample it continues
// with sample `restart`, time shifted so that it keeps increasing by T.
class Feeder {
 public:
  Feeder(const Record& r, Eigen::Index restart) : r_(r), restart_(restart), k_(0) {}
  Sample next() {
    if (k_ == r_.size()) {
      offset_ += r_.t(r_.size() - 1) + r_.sample_time() - r_.t(restart_);
      k_ = restart_;
    }
    const Eigen::Index k = k_++;
    return Sample{r_.t(k) + offset_, r_.u(k), r_.y(k), r_.has_reference() ? r_.r(k) : 0.0};
  }

 private:
  const Record& r_;
  Eigen::Index restart_, k_;
  double offset_ = 0.0;
};

}  // namespace modalwatch::bench
