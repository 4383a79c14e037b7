// Product and Gauss-Seidel sweeps over a lower block triangle (see lower_kernels.h): a plain
// build and an AVX2 build of the same operations in the same order.
#include "cloth/lower_kernels.h"

#include <algorithm>
#include <atomic>

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
#define SIMBAKE_HAVE_AVX2_BUILD 1
#endif

namespace simbake::cloth_detail {

namespace {

// ---- plain build

// t_r = (f_r y_0 + f_(3+r) y_1) + f_(6+r) y_2: a block (column-major floats) times a vector
inline void block_times(const float* f, const double* y, double t[3]) {
  for (int r = 0; r < 3; ++r) {
    t[r] = (static_cast<double>(f[r]) * y[0] + static_cast<double>(f[3 + r]) * y[1]) + static_cast<double>(f[6 + r]) * y[2];
  }
}

// t_c = (f_(3c) y_0 + f_(3c+1) y_1) + f_(3c+2) y_2: the block's transpose times a vector
inline void transpose_times(const float* f, const double* y, double t[3]) {
  for (int c = 0; c < 3; ++c) {
    t[c] = (static_cast<double>(f[3 * c]) * y[0] + static_cast<double>(f[3 * c + 1]) * y[1]) +
           static_cast<double>(f[3 * c + 2]) * y[2];
  }
}

// x_r = (a_r s_0 + a_(3+r) s_1) + a_(6+r) s_2 (a 3x3 double matrix, column-major)
inline void solve3(const double* a, const double* s, double* x) {
  for (int r = 0; r < 3; ++r) x[r] = (a[r] * s[0] + a[3 + r] * s[1]) + a[6 + r] * s[2];
}

double product_plain(const LowerView& a, const double* x, double* y) {
  std::fill(y, y + 3 * a.size, 0.0);
  double xax = 0.0;
  for (int i = 0; i < a.size; ++i) {
    const double* xi = x + 3 * i;
    const int last = a.start[i + 1] - 1;
    double s[3] = {0.0, 0.0, 0.0}, t[3];
    for (int k = a.start[i]; k < last; ++k) {
      const float* f = a.block + 9 * k;
      const int j = a.column[k];
      block_times(f, x + 3 * j, t);
      for (int r = 0; r < 3; ++r) s[r] += t[r];
      transpose_times(f, xi, t);
      for (int r = 0; r < 3; ++r) y[3 * j + r] += t[r];
    }
    double d[3];
    block_times(a.block + 9 * last, xi, d);
    double v[3];
    for (int r = 0; r < 3; ++r) v[r] = 2.0 * s[r] + d[r];
    xax += (xi[0] * v[0] + xi[1] * v[1]) + xi[2] * v[2];
    for (int r = 0; r < 3; ++r) y[3 * i + r] += s[r] + d[r];
  }
  return xax;
}

// Row i of a sweep: s = b_i (or b_i - out_i backward) less the row's blocks times x,
// x_i = D_i^-1 s, then the blocks' transposes times x_i taken from out (forward: the
// residual) or added to it (backward: the rows before i)
template <bool kBackward>
void sweep_plain(const LowerView& a, const double* inverse, const double* b, double* x, double* out) {
  std::fill(out, out + 3 * a.size, 0.0);
  for (int n = 0; n < a.size; ++n) {
    const int i = kBackward ? a.size - 1 - n : n;
    const int last = a.start[i + 1] - 1;
    double s[3], t[3];
    for (int r = 0; r < 3; ++r) s[r] = kBackward ? b[3 * i + r] - out[3 * i + r] : b[3 * i + r];
    for (int k = a.start[i]; k < last; ++k) {
      block_times(a.block + 9 * k, x + 3 * a.column[k], t);
      for (int r = 0; r < 3; ++r) s[r] -= t[r];
    }
    solve3(inverse + 9 * i, s, x + 3 * i);
    for (int k = a.start[i]; k < last; ++k) {
      transpose_times(a.block + 9 * k, x + 3 * i, t);
      for (int r = 0; r < 3; ++r) {
        if (kBackward) {
          out[3 * a.column[k] + r] += t[r];
        } else {
          out[3 * a.column[k] + r] -= t[r];
        }
      }
    }
  }
}

#ifdef SIMBAKE_HAVE_AVX2_BUILD

// ---- AVX2 build: a 3-vector in lanes 0-2 of a register (lane 3 is never stored)

#define SIMBAKE_AVX2 __attribute__((target("avx2")))

SIMBAKE_AVX2 inline __m256i lanes3() { return _mm256_set_epi64x(0, -1, -1, -1); }
SIMBAKE_AVX2 inline __m256d load3(const double* p) { return _mm256_maskload_pd(p, lanes3()); }
SIMBAKE_AVX2 inline void store3(double* p, __m256d v) { _mm256_maskstore_pd(p, lanes3(), v); }

// the block's three columns, converted (each load reads one float past the column)
struct Columns {
  __m256d c0, c1, c2;
};
SIMBAKE_AVX2 inline Columns columns(const float* f) {
  return {_mm256_cvtps_pd(_mm_loadu_ps(f)), _mm256_cvtps_pd(_mm_loadu_ps(f + 3)), _mm256_cvtps_pd(_mm_loadu_ps(f + 6))};
}

// lanes r: (c0_r y_0 + c1_r y_1) + c2_r y_2
SIMBAKE_AVX2 inline __m256d times(const Columns& c, const double* y) {
  __m256d t = _mm256_mul_pd(c.c0, _mm256_broadcast_sd(y));
  t = _mm256_add_pd(t, _mm256_mul_pd(c.c1, _mm256_broadcast_sd(y + 1)));
  return _mm256_add_pd(t, _mm256_mul_pd(c.c2, _mm256_broadcast_sd(y + 2)));
}

// (p_0 + p_1) + p_2 of p = c_k * y lane by lane, for the three columns: the transpose times y,
// added to (kAdd) or taken from out[0..2]
template <bool kAdd>
SIMBAKE_AVX2 inline void transpose_times_into(const Columns& c, __m256d y, double* out) {
  const __m256d p0 = _mm256_mul_pd(c.c0, y), p1 = _mm256_mul_pd(c.c1, y), p2 = _mm256_mul_pd(c.c2, y);
  const __m256d low = _mm256_unpacklo_pd(p0, p1);   // p0_0 p1_0 p0_2 p1_2
  const __m256d high = _mm256_unpackhi_pd(p0, p1);  // p0_1 p1_1 p0_3 p1_3
  const __m128d t01 = _mm_add_pd(_mm_add_pd(_mm256_castpd256_pd128(low), _mm256_castpd256_pd128(high)),
                                 _mm256_extractf128_pd(low, 1));
  const __m128d q = _mm256_castpd256_pd128(p2);
  const __m128d t2 = _mm_add_sd(_mm_add_sd(q, _mm_unpackhi_pd(q, q)), _mm256_extractf128_pd(p2, 1));
  if (kAdd) {
    _mm_storeu_pd(out, _mm_add_pd(_mm_loadu_pd(out), t01));
    _mm_store_sd(out + 2, _mm_add_sd(_mm_load_sd(out + 2), t2));
  } else {
    _mm_storeu_pd(out, _mm_sub_pd(_mm_loadu_pd(out), t01));
    _mm_store_sd(out + 2, _mm_sub_sd(_mm_load_sd(out + 2), t2));
  }
}

// lanes r: (a_r s_0 + a_(3+r) s_1) + a_(6+r) s_2 (reads one double past the matrix)
SIMBAKE_AVX2 inline __m256d solve3(const double* a, __m256d s) {
  __m256d x = _mm256_mul_pd(_mm256_loadu_pd(a), _mm256_permute4x64_pd(s, 0x00));
  x = _mm256_add_pd(x, _mm256_mul_pd(_mm256_loadu_pd(a + 3), _mm256_permute4x64_pd(s, 0x55)));
  return _mm256_add_pd(x, _mm256_mul_pd(_mm256_loadu_pd(a + 6), _mm256_permute4x64_pd(s, 0xAA)));
}

// (p_0 + p_1) + p_2
SIMBAKE_AVX2 inline double sum3(__m256d p) {
  const __m128d q = _mm256_castpd256_pd128(p);
  return _mm_cvtsd_f64(_mm_add_sd(_mm_add_sd(q, _mm_unpackhi_pd(q, q)), _mm256_extractf128_pd(p, 1)));
}

SIMBAKE_AVX2 double product_avx2(const LowerView& a, const double* x, double* y) {
  std::fill(y, y + 3 * a.size, 0.0);
  double xax = 0.0;
  const __m256d two = _mm256_set1_pd(2.0);
  for (int i = 0; i < a.size; ++i) {
    const double* xi = x + 3 * i;
    const __m256d vi = load3(xi);
    const int last = a.start[i + 1] - 1;
    __m256d s = _mm256_setzero_pd();
    for (int k = a.start[i]; k < last; ++k) {
      const Columns c = columns(a.block + 9 * k);
      const int j = a.column[k];
      s = _mm256_add_pd(s, times(c, x + 3 * j));
      transpose_times_into<true>(c, vi, y + 3 * j);
    }
    const __m256d d = times(columns(a.block + 9 * last), xi);
    xax += sum3(_mm256_mul_pd(vi, _mm256_add_pd(_mm256_mul_pd(two, s), d)));
    store3(y + 3 * i, _mm256_add_pd(load3(y + 3 * i), _mm256_add_pd(s, d)));
  }
  return xax;
}

template <bool kBackward>
SIMBAKE_AVX2 void sweep_avx2(const LowerView& a, const double* inverse, const double* b, double* x, double* out) {
  std::fill(out, out + 3 * a.size, 0.0);
  for (int n = 0; n < a.size; ++n) {
    const int i = kBackward ? a.size - 1 - n : n;
    const int last = a.start[i + 1] - 1;
    __m256d s = kBackward ? _mm256_sub_pd(load3(b + 3 * i), load3(out + 3 * i)) : load3(b + 3 * i);
    for (int k = a.start[i]; k < last; ++k) s = _mm256_sub_pd(s, times(columns(a.block + 9 * k), x + 3 * a.column[k]));
    const __m256d xi = solve3(inverse + 9 * i, s);
    store3(x + 3 * i, xi);
    for (int k = a.start[i]; k < last; ++k) transpose_times_into<kBackward>(columns(a.block + 9 * k), xi, out + 3 * a.column[k]);
  }
}

#endif  // SIMBAKE_HAVE_AVX2_BUILD

std::atomic<bool>& avx2_on() {
  static std::atomic<bool> on{avx2_available()};
  return on;
}

}  // namespace

bool avx2_available() {
#ifdef SIMBAKE_HAVE_AVX2_BUILD
  return __builtin_cpu_supports("avx2");
#else
  return false;
#endif
}

bool use_avx2(bool on) { return avx2_on().exchange(on && avx2_available()); }

double lower_product(const LowerView& a, const double* x, double* y) {
#ifdef SIMBAKE_HAVE_AVX2_BUILD
  if (avx2_on().load(std::memory_order_relaxed)) return product_avx2(a, x, y);
#endif
  return product_plain(a, x, y);
}

void forward_sweep(const LowerView& a, const double* inverse, const double* b, double* x, double* res) {
#ifdef SIMBAKE_HAVE_AVX2_BUILD
  if (avx2_on().load(std::memory_order_relaxed)) return sweep_avx2<false>(a, inverse, b, x, res);
#endif
  sweep_plain<false>(a, inverse, b, x, res);
}

void backward_sweep(const LowerView& a, const double* inverse, const double* b, double* x, double* ahead) {
#ifdef SIMBAKE_HAVE_AVX2_BUILD
  if (avx2_on().load(std::memory_order_relaxed)) return sweep_avx2<true>(a, inverse, b, x, ahead);
#endif
  sweep_plain<true>(a, inverse, b, x, ahead);
}

}  // namespace simbake::cloth_detail
