// The CSV record reader, as `fit` (clean, equidistant) and `track`/`replay`
// (NaN and gaps allowed) call it: InputError or a record whose time increases.
#include <cstdint>
#include <cstdlib>
#include <string_view>

#include "modalwatch/error.hpp"
#include "modalwatch/io/csv.hpp"
#include "modalwatch/io/records.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size > 1 << 16) return 0;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  for (const bool tolerant : {false, true}) {
    modalwatch::RecordReadOptions options;
    options.allow_nonfinite = tolerant;
    options.allow_gaps = tolerant;
    try {
      const modalwatch::Record r = modalwatch::parse_record(text, "fuzz.csv", {}, options);
      if (r.size() < 1 || r.u.size() != r.size() || r.y.size() != r.size()) std::abort();
      for (Eigen::Index k = 1; k < r.size(); ++k)
        if (!(r.t(k) > r.t(k - 1))) std::abort();
    } catch (const modalwatch::InputError&) {
    }
  }
  try {
    (void)modalwatch::parse_table(text, "fuzz.csv");
  } catch (const modalwatch::InputError&) {
  }
  return 0;
}
