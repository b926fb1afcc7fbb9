// GIMLOD_VECTOR_CLONES before a function with hot vector loops: on x86-64 the compiler makes an
// AVX2 copy besides the baseline (SSE2) one, and the loader picks by the CPU at start (GCC and
// clang function multi-versioning, an ifunc). Both compute the same: AVX2 brings no fused
// multiply-add, so float results stay bit for bit those of the baseline. Elsewhere it is empty;
// so it is under ThreadSanitizer, whose runtime is not up yet when the loader runs an ifunc's
// resolver (the program crashes at start), and where GIMLOD_NO_VECTOR_CLONES is defined.
#pragma once

#if defined(__SANITIZE_THREAD__)
#define GIMLOD_THREAD_SANITIZER 1
#elif defined(__has_feature)
#if __has_feature(thread_sanitizer)
#define GIMLOD_THREAD_SANITIZER 1
#endif
#endif

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__)) && !defined(GIMLOD_NO_VECTOR_CLONES) && \
    !defined(GIMLOD_THREAD_SANITIZER)
#define GIMLOD_VECTOR_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define GIMLOD_VECTOR_CLONES
#endif
