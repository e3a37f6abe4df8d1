/* Scan, stable radix sort and grouping of int keys, the data-parallel
 * primitives the irradiance cache groups points with. Every work item owns
 * one chunk of consecutive elements and walks it in order, which keeps the
 * sort stable: equal keys stay in index order, so sums over a group are the
 * same on every run. Host side: gpu_core/cache_sort.py. */

/* values[i] = i. */
__kernel void Cache_iota(__global int *values, const int n) {
    int i = get_global_id(0);
    if (i < n) values[i] = i;
}

/* Exclusive scan of a short array by one work item; total[0] = the sum. */
__kernel void Cache_scan_serial(__global int *data, const int n, __global int *total) {
    if (get_global_id(0) != 0) return;
    int sum = 0;
    for (int i = 0; i < n; ++i) {
        int v = data[i];
        data[i] = sum;
        sum += v;
    }
    total[0] = sum;
}

/* Sum of each chunk of `chunk` elements. */
__kernel void Cache_scan_reduce(const __global int *data, const int n, const int chunk,
                                __global int *sums, const int chunks) {
    int c = get_global_id(0);
    if (c >= chunks) return;
    int end = min(n, (c + 1) * chunk);
    int sum = 0;
    for (int i = c * chunk; i < end; ++i) sum += data[i];
    sums[c] = sum;
}

/* Exclusive scan inside each chunk, starting from the chunk's scanned sum. */
__kernel void Cache_scan_apply(__global int *data, const int n, const int chunk,
                               const __global int *offsets, const int chunks) {
    int c = get_global_id(0);
    if (c >= chunks) return;
    int end = min(n, (c + 1) * chunk);
    int sum = offsets[c];
    for (int i = c * chunk; i < end; ++i) {
        int v = data[i];
        data[i] = sum;
        sum += v;
    }
}

#define CACHE_RADIX 16 /* 4-bit digits */

/* Per chunk, how many keys have each digit; stored digit-major so one
 * exclusive scan of the table gives every (digit, chunk) its first slot. */
__kernel void Cache_radix_count(const __global uint *keys, const int n, const int shift,
                                const int chunk, __global int *table, const int chunks) {
    int c = get_global_id(0);
    if (c >= chunks) return;
    int hist[CACHE_RADIX];
    for (int d = 0; d < CACHE_RADIX; ++d) hist[d] = 0;
    int end = min(n, (c + 1) * chunk);
    for (int i = c * chunk; i < end; ++i) hist[(keys[i] >> shift) & (CACHE_RADIX - 1)]++;
    for (int d = 0; d < CACHE_RADIX; ++d) table[d * chunks + c] = hist[d];
}

/* Move each (key, value) of the chunk to its slot, in order (stable). */
__kernel void Cache_radix_scatter(const __global uint *keys, const __global int *values,
                                  __global uint *keys_out, __global int *values_out,
                                  const int n, const int shift, const int chunk,
                                  const __global int *table, const int chunks) {
    int c = get_global_id(0);
    if (c >= chunks) return;
    int slot[CACHE_RADIX];
    for (int d = 0; d < CACHE_RADIX; ++d) slot[d] = table[d * chunks + c];
    int end = min(n, (c + 1) * chunk);
    for (int i = c * chunk; i < end; ++i) {
        uint key = keys[i];
        int at = slot[(key >> shift) & (CACHE_RADIX - 1)]++;
        keys_out[at] = key;
        values_out[at] = values[i];
    }
}

/* For sorted keys, [start[k], end[k]) is the run of key k; both arrays are
 * zero beforehand, so absent keys give empty runs. */
__kernel void Cache_group_ranges(const __global uint *keys, const int n, __global int *start,
                                 __global int *end) {
    int i = get_global_id(0);
    if (i >= n) return;
    uint key = keys[i];
    if (i == 0 || keys[i - 1] != key) start[key] = i;
    if (i == n - 1 || keys[i + 1] != key) end[key] = i + 1;
}
