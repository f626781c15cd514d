// A minimal driver for instruction counts (valgrind --tool=callgrind): the
// seed paper's K = 3 closed-loop case with M_s = 0, warm-up (1000 samples,
// offline fit) and then N steps. scripts/measure/bench.sh runs it for two N and takes
// (Ir(N2) - Ir(N1)) / (N2 - N1) as the instructions per sample of step().
//
//   step_driver [N [KERNEL]]   (N default: $MODALWATCH_STEPS, else 100000;
//                               KERNEL portable or avx2_fma, default: the CPU's best)
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "bench_common.hpp"

int main(int argc, char** argv) {
  using namespace modalwatch;
  using namespace modalwatch::bench;
  long long n = 100000;
  if (const char* env = std::getenv("MODALWATCH_STEPS")) n = std::atoll(env);
  if (argc > 1) n = std::atoll(argv[1]);
  const char* kernel = argc > 2 ? argv[2] : nullptr;
  if (n < 0 || (kernel && std::strcmp(kernel, "portable") != 0 && std::strcmp(kernel, "avx2_fma") != 0)) {
    std::fprintf(stderr, "usage: step_driver [N >= 0 [portable|avx2_fma]]\n");
    return 2;
  }
  constexpr int kWarmup = 1000;
  const Config& config = paper_config();
  EstimatorSettings s = config.estimator;
  s.closed_loop = true;
  s.refinements = 0;
  s.block_iterations = 1;
  s.update_divisor = 1;
  s.warmup_samples = kWarmup;
  // A fixed record (the same work whatever N), fed in a loop.
  const Record r = simulate_paper(3, true, 1000.0);
  RecursiveEstimator est(config.model, s);
  if (kernel &&
      !est.set_step_kernel(std::strcmp(kernel, "portable") == 0 ? StepKernel::portable : StepKernel::avx2_fma)) {
    std::fprintf(stderr, "step_driver: this CPU cannot run the %s kernel\n", kernel);
    return 1;
  }
  Feeder feed(r, kWarmup);
  for (int k = 0; k < kWarmup + 100; ++k) est.step(feed.next());
  unsigned flags = 0;
  for (long long k = 0; k < n; ++k) flags |= est.step(feed.next());
  const EstimatorStatus& st = est.status();
  const ModeEstimate m = est.mode(2);
  std::printf("step_driver: %lld steps (%s kernel), updates %llu, resets %llu, covariance clamps %llu, flags %u, "
              "mode3 wn %.6g\n",
              n, est.step_kernel() == StepKernel::portable ? "portable" : "avx2_fma",
              static_cast<unsigned long long>(st.updates), static_cast<unsigned long long>(st.resets),
              static_cast<unsigned long long>(st.covariance_clamps), flags,
              m.value.wn);
  return 0;
}
