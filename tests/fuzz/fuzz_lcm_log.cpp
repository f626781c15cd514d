// libFuzzer target: parse_lcm_log on any bytes (scripts/check/fuzz.sh), for a
// model of one input or of two (by the input's size). Properties: only
// InputError escapes; a parsed record has one offset per sample, equal column
// lengths, the model's inputs, t from 0 and strictly increasing.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <span>

#include "modalwatch/error.hpp"
#include "modalwatch/io/lcm_log.hpp"

using namespace modalwatch;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  LcmLogOptions o;
  o.closed_loop = size % 2 == 1;
  o.channel = size % 3 == 0 ? "MODALWATCH_SAMPLES" : "";
  o.inputs = size % 5 == 0 ? 2 : 1;
  try {
    const LcmLogRecord r = parse_lcm_log(std::span(data, size), "fuzz", o);
    const Record& rec = r.record;
    const auto n = rec.size();
    if (n < 1 || rec.u.size() != n || rec.y.size() != n || static_cast<Eigen::Index>(r.offsets.size()) != n)
      std::abort();
    if (o.closed_loop != rec.has_reference()) std::abort();
    if (rec.inputs() != o.inputs) std::abort();
    for (const auto& v : rec.further_u)
      if (v.size() != n) std::abort();
    if (rec.t(0) != 0.0) std::abort();
    for (Eigen::Index k = 1; k < n; ++k)
      if (!(rec.t(k) > rec.t(k - 1))) std::abort();
  } catch (const InputError&) {
  }
  return 0;
}
