// The YAML configuration loader: any text either parses into a Config or throws
// InputError (naming file, line and key). Any other exception, a crash, a leak
// or undefined behaviour is a finding.
#include <cstdint>
#include <cstdlib>
#include <string>

#include "modalwatch/error.hpp"
#include "modalwatch/io/config.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size > 1 << 16) return 0;
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    const modalwatch::Config config = modalwatch::parse_config(text, "fuzz.yaml");
    // A loaded config must survive its own round trip.
    const modalwatch::Config again =
        modalwatch::parse_config(modalwatch::config_to_yaml(config, config.model), "again.yaml");
    if (again.model.submodels.size() != config.model.submodels.size()) std::abort();
  } catch (const modalwatch::InputError&) {
  }
  return 0;
}
