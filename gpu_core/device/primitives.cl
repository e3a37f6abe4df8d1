/* Device primitives: prefix sums, reductions, compaction, index ramps, a
 * stable radix sort and the runs of sorted keys (host side:
 * gpu_core/device/primitives.py). One small program: a render starts fast
 * (each of pyopencl's generic scan and reduction kernels costs seconds of
 * compilation on the CPU device).
 *
 * Every work item owns one chunk of PRIM_CHUNK consecutive elements and
 * walks it in order: sums come out the same on every run, and the sort is
 * stable (equal keys stay in index order). */
#include "device/launch.h"

#define PRIM_CHUNK 256
#define PRIM_RADIX (1 << PRIM_RADIX_BITS)

/* ---- prefix sums of int, long and int8 ---------------------------------
 * Exclusive (or inclusive) prefix sums, in place allowed; the total goes to
 * total[0]. Short arrays: one work item. Longer ones: each chunk's sum,
 * the chunk sums scanned (by the host, recursively), then each chunk
 * rescanned from its offset. */
#define PRIM_SCAN(T, NAME)                                                                        \
    __kernel void Prim_scan_serial_##NAME(const __global T *in, __global T *out, const int n,     \
                                          const int inclusive, __global T *total) {               \
        if (Launch_global_id() != 0) return;                                                      \
        T sum = (T)(0);                                                                           \
        for (int i = 0; i < n; ++i) {                                                             \
            T v = in[i];                                                                          \
            out[i] = inclusive ? sum + v : sum;                                                   \
            sum += v;                                                                             \
        }                                                                                         \
        total[0] = sum;                                                                           \
    }                                                                                             \
    __kernel void Prim_scan_reduce_##NAME(const __global T *in, const int n, __global T *sums,   \
                                          const int chunks) {                                     \
        int c = Launch_global_id();                                                               \
        if (c >= chunks) return;                                                                  \
        T sum = (T)(0);                                                                           \
        for (int i = c * PRIM_CHUNK, end = min(n, i + PRIM_CHUNK); i < end; ++i) sum += in[i];    \
        sums[c] = sum;                                                                            \
    }                                                                                             \
    __kernel void Prim_scan_apply_##NAME(const __global T *in, __global T *out, const int n,      \
                                         const int inclusive, const __global T *offsets,          \
                                         const int chunks) {                                      \
        int c = Launch_global_id();                                                               \
        if (c >= chunks) return;                                                                  \
        T sum = offsets[c];                                                                       \
        for (int i = c * PRIM_CHUNK, end = min(n, i + PRIM_CHUNK); i < end; ++i) {                \
            T v = in[i];                                                                          \
            out[i] = inclusive ? sum + v : sum;                                                   \
            sum += v;                                                                             \
        }                                                                                         \
    }

PRIM_SCAN(int, int)
PRIM_SCAN(long, long)
PRIM_SCAN(int8, int8)

/* ---- reductions --------------------------------------------------------
 * out[c] = the reduction of chunk c; the host reduces the partials again
 * until one is left. */
#define PRIM_REDUCE(T, ACC, NAME, ZERO, COMBINE)                                                  \
    __kernel void Prim_reduce_##NAME(const __global T *in, const int n, __global ACC *out,        \
                                     const int chunks) {                                          \
        int c = Launch_global_id();                                                               \
        if (c >= chunks) return;                                                                  \
        ACC acc = ZERO;                                                                           \
        for (int i = c * PRIM_CHUNK, end = min(n, i + PRIM_CHUNK); i < end; ++i) {                \
            T b = in[i];                                                                          \
            acc = COMBINE(acc, b);                                                                \
        }                                                                                         \
        out[c] = acc;                                                                             \
    }

#define PRIM_ADD(a, b) ((a) + (b))
PRIM_REDUCE(int4, int4, sum_int4, (int4)(0), PRIM_ADD)
PRIM_REDUCE(int4, int4, max_int4, (int4)(INT_MIN), max)

/* Bounds of float4 points in one pass over them: each partial a float8 of
 * the lanes' minima (lo half) and maxima (hi half), reduced again as such. */
inline float8 Prim_bounds_union(float8 a, float8 b) { return (float8)(fmin(a.lo, b.lo), fmax(a.hi, b.hi)); }
inline float8 Prim_bounds_add(float8 a, float4 p) { return (float8)(fmin(a.lo, p), fmax(a.hi, p)); }
#define PRIM_BOUNDS_EMPTY (float8)((float4)(INFINITY), (float4)(-INFINITY))
PRIM_REDUCE(float4, float8, bounds_float4, PRIM_BOUNDS_EMPTY, Prim_bounds_add)
PRIM_REDUCE(float8, float8, bounds_float8, PRIM_BOUNDS_EMPTY, Prim_bounds_union)

/* Sums of float4 to float64 accuracy: each value is a float8 of the sum
 * (lo half) and the rounding error the sum lost (hi half), combined by
 * Knuth's two-sum, so the result does not depend on how rounding fell. */
inline float8 Prim_two_sum(float8 a, float8 b) {
    float4 s = a.lo + b.lo;
    float4 bp = s - a.lo;
    float4 err = (a.lo - (s - bp)) + (b.lo - bp);
    return (float8)(s, a.hi + b.hi + err);
}
PRIM_REDUCE(float8, float8, sum_float8, (float8)(0.0f), Prim_two_sum)

/* float4 values as (value, no error) float8s, for Prim_reduce_sum_float8. */
__kernel void Prim_float8_of(const __global float4 *in, const int n, __global float8 *out) {
    int i = Launch_global_id();
    if (i < n) out[i] = (float8)(in[i], (float4)(0.0f));
}

/* n packed 3-vectors (in: x, y, z, x, ...) as float4 rows with w = 0. */
__kernel void Prim_float4_of_float3(const __global float *in, const int n, __global float4 *out) {
    int i = Launch_global_id();
    if (i < n) out[i] = (float4)(in[3 * i], in[3 * i + 1], in[3 * i + 2], 0.0f);
}

/* int values as (value, 0, 0, 0) int4s, for the int4 reductions. */
__kernel void Prim_int4_of(const __global int *in, const int n, __global int4 *out) {
    int i = Launch_global_id();
    if (i < n) out[i] = (int4)(in[i], 0, 0, 0);
}

/* ---- comparison --------------------------------------------------------- */

/* flag[0] = 1 where a chunk of the n ints of a and b differs (bit for bit;
 * the host clears the flag first). */
__kernel void Prim_flag_difference(const __global int *a, const __global int *b, const int n,
                                   __global int *flag, const int chunks) {
    int c = Launch_global_id();
    if (c >= chunks) return;
    int differ = 0;
    for (int i = c * PRIM_CHUNK, end = min(n, i + PRIM_CHUNK); i < end; ++i) differ |= a[i] ^ b[i];
    if (differ) flag[0] = 1;
}

/* ---- compaction and gathers -------------------------------------------- */

/* base + i for every i whose flag is set, at its exclusive prefix sum. */
__kernel void Prim_compact(const __global int *flags, const __global int *scanned, const int n, const int base,
                           __global int *out) {
    int i = Launch_global_id();
    if (i < n && flags[i]) out[scanned[i]] = base + i;
}

/* out[i] = values[index[i]] for float4 rows. */
__kernel void Prim_gather_float4(const __global float4 *values, const __global int *index, const int n,
                                 __global float4 *out) {
    int i = Launch_global_id();
    if (i < n) out[i] = values[index[i]];
}

/* out[index[i]] = values[i] for float4 rows. */
__kernel void Prim_scatter_float4(const __global float4 *values, const __global int *index, const int n,
                                  __global float4 *out) {
    int i = Launch_global_id();
    if (i < n) out[index[i]] = values[i];
}

/* out[i] = values[index[i]] for ints. */
__kernel void Prim_gather_int(const __global int *values, const __global int *index, const int n, __global int *out) {
    int i = Launch_global_id();
    if (i < n) out[i] = values[index[i]];
}

/* Each point with its index in w (int bits), as the point-tree builder takes them. */
__kernel void Prim_indexed_points(const __global float4 *points, const int n, __global float4 *out) {
    int i = Launch_global_id();
    if (i < n) out[i] = (float4)(points[i].xyz, as_float(i));
}

/* values[i] = i. */
__kernel void Prim_iota(__global int *values, const int n) {
    int i = Launch_global_id();
    if (i < n) values[i] = i;
}

/* ---- stable radix sort and group-by-key -------------------------------- */

/* Per chunk, how many keys have each digit; stored digit-major so one
 * exclusive scan of the table gives every (digit, chunk) its first slot. */
__kernel void Prim_radix_count(const __global uint *keys, const int n, const int shift, __global int *table,
                               const int chunks) {
    int c = Launch_global_id();
    if (c >= chunks) return;
    int hist[PRIM_RADIX];
    for (int d = 0; d < PRIM_RADIX; ++d) hist[d] = 0;
    for (int i = c * PRIM_CHUNK, end = min(n, i + PRIM_CHUNK); i < end; ++i)
        hist[(keys[i] >> shift) & (PRIM_RADIX - 1)]++;
    for (int d = 0; d < PRIM_RADIX; ++d) table[d * chunks + c] = hist[d];
}

/* Move each (key, value) of the chunk to its slot, in order (stable). */
__kernel void Prim_radix_scatter(const __global uint *keys, const __global int *values, __global uint *keys_out,
                                 __global int *values_out, const int n, const int shift, const __global int *table,
                                 const int chunks) {
    int c = Launch_global_id();
    if (c >= chunks) return;
    int slot[PRIM_RADIX];
    for (int d = 0; d < PRIM_RADIX; ++d) slot[d] = table[d * chunks + c];
    for (int i = c * PRIM_CHUNK, end = min(n, i + PRIM_CHUNK); i < end; ++i) {
        uint key = keys[i];
        int at = slot[(key >> shift) & (PRIM_RADIX - 1)]++;
        keys_out[at] = key;
        values_out[at] = values[i];
    }
}

/* The whole stable radix sort of a short array by one work-group (of up
 * to PRIM_SORT_GROUP work-items; one on a CPU device): `passes` passes of
 * PRIM_RADIX_BITS, each work-item owning a run of consecutive elements as a
 * chunk above, the digit table in local memory, so that the sort is one
 * launch where the chunked one is three a pass. Pass p reads what pass
 * p - 1 wrote (the input first) and writes the pair of outputs p % 2; the
 * values are the elements' indices where `indices` is set. The same order
 * as the chunked sort (a stable sort has one result). */
__kernel void Prim_radix_sort_group(const __global uint *keys, const __global int *values, const int indices,
                                    const int n, const int passes, __global uint *keys0, __global int *values0,
                                    __global uint *keys1, __global int *values1) {
    __local int table[PRIM_RADIX * PRIM_SORT_GROUP], partial[PRIM_SORT_GROUP];
    int t = get_local_id(0), size = get_local_size(0);
    int run = (n + size - 1) / size, lo = min(t * run, n), hi = min(lo + run, n);
    for (int p = 0; p < passes; ++p) {
        const __global uint *k_in = p == 0 ? keys : (p % 2 ? keys0 : keys1);
        const __global int *v_in = p == 0 ? values : (p % 2 ? values0 : values1);
        __global uint *k_out = p % 2 ? keys1 : keys0;
        __global int *v_out = p % 2 ? values1 : values0;
        int shift = p * PRIM_RADIX_BITS, slot[PRIM_RADIX];
        for (int d = 0; d < PRIM_RADIX; ++d) slot[d] = 0;
        for (int i = lo; i < hi; ++i) slot[(k_in[i] >> shift) & (PRIM_RADIX - 1)]++;
        for (int d = 0; d < PRIM_RADIX; ++d) table[d * size + t] = slot[d];
        barrier(CLK_LOCAL_MEM_FENCE);
        /* digit-major exclusive prefix sums (each digit's runs in work-item
         * order): each work-item scans PRIM_RADIX entries of the table,
         * their sums are scanned, then added back */
        int base = t * PRIM_RADIX, sum = 0;
        for (int j = base; j < base + PRIM_RADIX; ++j) {
            int c = table[j];
            table[j] = sum;
            sum += c;
        }
        partial[t] = sum;
        barrier(CLK_LOCAL_MEM_FENCE);
        if (t == 0) {
            int run_sum = 0;
            for (int j = 0; j < size; ++j) {
                int c = partial[j];
                partial[j] = run_sum;
                run_sum += c;
            }
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        for (int j = base; j < base + PRIM_RADIX; ++j) table[j] += partial[t];
        barrier(CLK_LOCAL_MEM_FENCE);
        for (int d = 0; d < PRIM_RADIX; ++d) slot[d] = table[d * size + t];
        for (int i = lo; i < hi; ++i) {
            uint key = k_in[i];
            int at = slot[(key >> shift) & (PRIM_RADIX - 1)]++;
            k_out[at] = key;
            v_out[at] = p == 0 && indices ? i : v_in[i];
        }
        /* this pass's output complete before the next reads it */
        barrier(CLK_LOCAL_MEM_FENCE | CLK_GLOBAL_MEM_FENCE);
    }
}

/* For sorted keys, [start[k], end[k]) is the run of key k; both arrays are
 * zero beforehand, so absent keys give empty runs. */
__kernel void Prim_group_ranges(const __global uint *keys, const int n, __global int *start, __global int *end) {
    int i = Launch_global_id();
    if (i >= n) return;
    uint key = keys[i];
    if (i == 0 || keys[i - 1] != key) start[key] = i;
    if (i == n - 1 || keys[i + 1] != key) end[key] = i + 1;
}
