#pragma once
// The per-sample path (advance() and everything inlined into it: the filter
// bank, the discretisation, eqs. 23-25 and the guards' checks) is compiled
// twice, in step.cpp: for the build's target (portable x86-64 by default) and,
// on x86-64, for AVX2 with fused multiply-add, where GCC contracts a * b + c
// into one instruction. Each estimator picks one at construction (no per-call
// dispatch, no global state). What the per-sample path inlines must therefore
// be visible in step.cpp: the private headers here, included by it.
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#define MODALWATCH_HAVE_AVX2_FMA 1
#define MODALWATCH_TARGET_AVX2_FMA [[gnu::target("avx2,fma")]]
#else
#define MODALWATCH_HAVE_AVX2_FMA 0
#define MODALWATCH_TARGET_AVX2_FMA
#endif
// Functions of the per-sample path: inlined into both compilations of it.
#define MODALWATCH_HOT [[gnu::always_inline]] inline
