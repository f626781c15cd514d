#pragma once
// Exit codes of every modalwatch subcommand: 0 success, 2 bad input (the
// message names the file and the key, or the row and column), 1 anything else.
#include <cstdio>
#include <exception>
#include <stdexcept>

#include "modalwatch/error.hpp"

namespace modalwatch::cli {

template <class F>
int guarded(const char* command, F&& body) {
  try {
    return body();
  } catch (const InputError& e) {
    std::fprintf(stderr, "modalwatch %s: %s\n", command, e.what());
    return 2;
  } catch (const std::invalid_argument& e) {
    std::fprintf(stderr, "modalwatch %s: %s\n", command, e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "modalwatch %s: error: %s\n", command, e.what());
    return 1;
  }
}

}  // namespace modalwatch::cli
