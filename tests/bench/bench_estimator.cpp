// Speed of the recursive estimator and of `modalwatch track`. Measured and
// reported, never asserted: scripts/measure/bench.sh builds Release and runs this,
// callgrind on step_driver and track on a 2M-sample record.
//
//   BM_Step/K/closed/Ms/fma step() after warm-up; items_per_second = samples/s (fma 1: the
//                           AVX2+FMA kernel, 0: portable)
//   BM_ReadRecord           the lenient CSV reader on a 1M-row record
//   BM_Track                `modalwatch track` end to end (CSV in and out), in process
#include <fcntl.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <map>
#include <string>
#include <tuple>

#include <benchmark/benchmark.h>

#include "bench_common.hpp"
#include "commands.hpp"
#include "modalwatch/io/records.hpp"

namespace modalwatch::bench {
namespace {

constexpr int kWarmup = 1000;

// Records simulated once per (K, loop): 100000 samples (5000 s at 20 Hz).
const Record& record(int K, bool closed) {
  static std::map<std::pair<int, bool>, Record> cache;
  auto it = cache.find({K, closed});
  if (it == cache.end()) it = cache.emplace(std::make_pair(K, closed), simulate_paper(K, closed, 5000.0)).first;
  return it->second;
}

void BM_Step(benchmark::State& state) {
  const int K = static_cast<int>(state.range(0));
  const bool closed = state.range(1) != 0;
  const Config config = paper_subset(K);
  EstimatorSettings s = config.estimator;
  s.closed_loop = closed;
  s.refinements = static_cast<int>(state.range(2));
  s.block_iterations = 1;
  s.update_divisor = 1;
  s.warmup_samples = kWarmup;
  const Record& r = record(K, closed);
  RecursiveEstimator est(config.model, s);
  // fma 1: the AVX2+FMA kernel (what the estimator picks where the CPU has it), 0: portable.
  if (!est.set_step_kernel(state.range(3) != 0 ? StepKernel::avx2_fma : StepKernel::portable)) {
    state.SkipWithError("this CPU cannot run the AVX2+FMA kernel");
    return;
  }
  Feeder feed(r, kWarmup);
  for (int k = 0; k < kWarmup + 100; ++k) est.step(feed.next());
  for (auto _ : state) {
    const unsigned flags = est.step(feed.next());
    benchmark::DoNotOptimize(flags);
  }
  state.SetItemsProcessed(state.iterations());
  const EstimatorStatus& st = est.status();
  state.counters["resets"] = static_cast<double>(st.resets);
  state.counters["outliers"] = static_cast<double>(st.outliers);
  state.counters["warmup_fit"] = st.warmup_fit_used ? 1.0 : 0.0;
}
BENCHMARK(BM_Step)
    ->ArgNames({"K", "closed", "Ms", "fma"})
    ->ArgsProduct({{2, 3}, {0, 1}, {0, 2}, {1, 0}})
    ->Unit(benchmark::kNanosecond);

// Files for the reader and track benchmarks, removed at exit.
class BenchFiles {
 public:
  BenchFiles() : dir_(std::filesystem::temp_directory_path() / ("modalwatch_bench_" + std::to_string(::getpid()))) {
    std::filesystem::create_directories(dir_);
  }
  ~BenchFiles() {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }

 private:
  std::filesystem::path dir_;
};

BenchFiles& bench_files() {
  static BenchFiles files;
  return files;
}

// A K = 3 closed-loop record of `samples` rows, written once.
std::string record_file(Eigen::Index samples) {
  const std::string path = bench_files().path("paper_" + std::to_string(samples) + ".csv");
  if (!std::filesystem::exists(path))
    write_record(path, simulate_paper(3, true, static_cast<double>(samples) * paper_config().sample_time));
  return path;
}

void BM_ReadRecord(benchmark::State& state) {
  const std::string path = record_file(state.range(0));
  RecordReadOptions o;
  o.allow_nonfinite = true;
  o.allow_gaps = true;
  o.sample_time = paper_config().sample_time;
  Eigen::Index rows = 0;
  for (auto _ : state) {
    const Record r = read_record(path, o);
    rows += r.size();
    benchmark::DoNotOptimize(r.y.data());
  }
  state.SetItemsProcessed(rows);
  state.SetBytesProcessed(static_cast<std::int64_t>(std::filesystem::file_size(path)) * state.iterations());
}
BENCHMARK(BM_ReadRecord)->Arg(1'000'000)->Unit(benchmark::kMillisecond);

// stdout and stderr to /dev/null while track prints its summary and table.
class Silence {
 public:
  Silence() {
    std::fflush(stdout);
    std::fflush(stderr);
    out_ = ::dup(1);
    err_ = ::dup(2);
    const int null = ::open("/dev/null", O_WRONLY);
    ::dup2(null, 1);
    ::dup2(null, 2);
    ::close(null);
  }
  ~Silence() {
    std::fflush(stdout);
    std::fflush(stderr);
    ::dup2(out_, 1);
    ::dup2(err_, 2);
    ::close(out_);
    ::close(err_);
  }

 private:
  int out_ = -1, err_ = -1;
};

void BM_Track(benchmark::State& state) {
  cli::TrackArgs args;
  args.config = std::string(MODALWATCH_SOURCE_DIR) + "/config/paper-sim.yaml";
  args.data = record_file(state.range(0));
  args.out = bench_files().path("est.csv");
  args.progress = false;
  int code = 0;
  for (auto _ : state) {
    Silence quiet;
    code |= cli::track(args);
  }
  if (code != 0) state.SkipWithError("modalwatch track failed");
  state.SetItemsProcessed(state.range(0) * state.iterations());
  state.counters["est_csv_MB"] = static_cast<double>(std::filesystem::file_size(args.out)) / 1e6;
}
BENCHMARK(BM_Track)->Arg(200'000)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
}  // namespace modalwatch::bench

BENCHMARK_MAIN();
