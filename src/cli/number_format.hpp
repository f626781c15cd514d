#pragma once
// est.csv's numbers. t and the estimates are written exactly (shortest
// round-trip, std::to_chars); their standard deviations to 6 significant
// digits, as printf's "%.6g" writes them: an uncertainty has no use for 17
// digits, and std::to_chars, shortest or with a precision, costs ~50 ns a
// number, the largest part of `modalwatch track`'s CPU time. write_6g is that
// format by scaling with a power of ten (~10 ns); where the scaled value is too
// close to a rounding boundary for the double product to decide, and for
// extreme magnitudes, it asks std::to_chars.
#include <array>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstdint>

namespace modalwatch::cli {

// Longest result of write_6g: "-1.23457e-308" (13 characters); of std::to_chars
// for a double: "-2.2250738585072014e-308" (24).
inline constexpr std::size_t kNumberChars = 24;

namespace number_format_detail {

inline constexpr int kMinPower = -310, kMaxPower = 310;

// 10^k for k in [kMinPower, kMaxPower] (std::pow is within an ulp: the
// tolerance below covers it). Filled before main, so a lookup has no guard.
inline const std::array<double, kMaxPower - kMinPower + 1> kPowersOfTen = [] {
  std::array<double, kMaxPower - kMinPower + 1> t{};
  for (int k = kMinPower; k <= kMaxPower; ++k) t[static_cast<std::size_t>(k - kMinPower)] = std::pow(10.0, k);
  return t;
}();

}  // namespace number_format_detail

// Writes v at `out` (room for kNumberChars) as "%.6g" and returns the end.
inline char* write_6g(char* out, double v) {
  using namespace number_format_detail;
  const double a = std::fabs(v);
  const auto fallback = [&] { return std::to_chars(out, out + kNumberChars, v, std::chars_format::general, 6).ptr; };
  if (!(a >= 1e-300 && a <= 1e300)) return fallback();  // 0, NaN, Inf, extremes
  const auto power = [](int k) { return kPowersOfTen[static_cast<std::size_t>(k - kMinPower)]; };
  // a in [2^(b-1), 2^b) with b the biased exponent - 1022 (a is normal here).
  const int b = static_cast<int>((std::bit_cast<std::uint64_t>(a) >> 52) & 0x7ff) - 1022;
  int e = ((b - 1) * 1233) >> 12;    // floor(log10(a)) within one (1233/4096 ~ log10 2)
  double scaled = a * power(5 - e);  // a * 10^(5-e), to be in [10^5, 10^6)
  if (scaled >= 1e6) scaled = a * power(5 - ++e);
  if (scaled < 1e5) scaled = a * power(5 - --e);
  if (scaled < 1e5 || scaled >= 1e6) return fallback();
  // The product is within a few ulps (of 10^6: < 1e-9) of the exact value:
  // decide the rounding only when it is clear of the halfway point.
  auto mantissa = static_cast<std::uint32_t>(scaled);  // floor: scaled > 0
  const double fraction = scaled - static_cast<double>(mantissa);
  if (std::fabs(fraction - 0.5) < 1e-7) return fallback();
  if (fraction > 0.5) ++mantissa;
  if (mantissa == 1000000) {  // rounded up to the next power of ten
    mantissa = 100000;
    ++e;
  }
  char digits[6];
  for (int i = 5; i >= 0; --i) {
    digits[i] = static_cast<char>('0' + mantissa % 10);
    mantissa /= 10;
  }
  int n = 6;  // significant digits without trailing zeros
  while (digits[n - 1] == '0') --n;
  if (std::signbit(v)) *out++ = '-';
  if (e >= -4 && e < 6) {  // fixed
    if (e >= 0) {
      for (int i = 0; i <= e; ++i) *out++ = digits[i];
      if (n > e + 1) {
        *out++ = '.';
        for (int i = e + 1; i < n; ++i) *out++ = digits[i];
      }
    } else {
      *out++ = '0';
      *out++ = '.';
      for (int i = 0; i < -e - 1; ++i) *out++ = '0';
      for (int i = 0; i < n; ++i) *out++ = digits[i];
    }
    return out;
  }
  *out++ = digits[0];  // scientific
  if (n > 1) {
    *out++ = '.';
    for (int i = 1; i < n; ++i) *out++ = digits[i];
  }
  *out++ = 'e';
  *out++ = e < 0 ? '-' : '+';
  const int x = e < 0 ? -e : e;
  if (x >= 100) *out++ = static_cast<char>('0' + x / 100);
  *out++ = static_cast<char>('0' + x / 10 % 10);
  *out++ = static_cast<char>('0' + x % 10);
  return out;
}

}  // namespace modalwatch::cli
