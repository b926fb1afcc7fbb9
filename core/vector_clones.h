// GIMLOD_VECTOR_CLONES before a function with hot vector loops: on x86-64 the compiler makes an
// AVX2 copy besides the baseline (SSE2) one, and the loader picks by the CPU at start (GCC and
// clang function multi-versioning, an ifunc). Both compute the same: AVX2 brings no fused
// multiply-add, so float results stay bit for bit those of the baseline. Elsewhere it is empty.
#pragma once

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__)) && !defined(GIMLOD_NO_VECTOR_CLONES)
#define GIMLOD_VECTOR_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define GIMLOD_VECTOR_CLONES
#endif
