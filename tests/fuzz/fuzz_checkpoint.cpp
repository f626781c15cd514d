// libFuzzer target: decode_checkpoint on any bytes (scripts/check/fuzz.sh). Built with
// FUZZING_BUILD_MODE_UNSAFE_FOR_PRODUCTION, which makes the decoder skip the
// CRC comparison so that mutations reach the payload parser. Properties: only
// InputError escapes; a decoded checkpoint re-encodes to the same bytes (CRC
// aside); restore() of its estimator state accepts it or throws invalid_argument.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <span>

#include "modalwatch/error.hpp"
#include "modalwatch/io/checkpoint.hpp"

using namespace modalwatch;

namespace {
RecursiveEstimator& estimator() {
  static RecursiveEstimator est = [] {
    AdditiveModel m;
    m.submodels = {make_mode("mode1", {2.0, 0.25, 3.0}), make_mode("mode2", {5.0, 0.025, 0.5}),
                   make_mode("mode3", {20.0, 0.1, 1.0})};
    EstimatorSettings s;
    s.sample_time = 0.05;
    return RecursiveEstimator(m, s);
  }();
  return est;
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  Checkpoint c;
  try {
    c = decode_checkpoint(std::span(data, size), "fuzz");
  } catch (const InputError&) {
    return 0;
  }
  const auto again = encode_checkpoint(c);
  if (again.size() != size || !std::equal(again.begin(), again.end() - 4, data)) std::abort();
  try {
    estimator().restore(c.estimator);
  } catch (const std::invalid_argument&) {
  }
  return 0;
}
