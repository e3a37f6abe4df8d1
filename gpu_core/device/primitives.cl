/* Device primitives beside pyopencl's scans: index ramps, a stable radix
 * sort and the runs of sorted keys. Every work item of the sort owns one
 * chunk of consecutive elements and walks it in order, which keeps it
 * stable: equal keys stay in index order, so sums over a group come out the
 * same on every run. Host side: gpu_core/device/primitives.py. */

#define PRIM_RADIX (1 << PRIM_RADIX_BITS)

/* values[i] = i. */
__kernel void Prim_iota(__global int *values, const int n) {
    int i = get_global_id(0);
    if (i < n) values[i] = i;
}

/* Per chunk, how many keys have each digit; stored digit-major so one
 * exclusive scan of the table gives every (digit, chunk) its first slot. */
__kernel void Prim_radix_count(const __global uint *keys, const int n, const int shift,
                               const int chunk, __global int *table, const int chunks) {
    int c = get_global_id(0);
    if (c >= chunks) return;
    int hist[PRIM_RADIX];
    for (int d = 0; d < PRIM_RADIX; ++d) hist[d] = 0;
    int end = min(n, (c + 1) * chunk);
    for (int i = c * chunk; i < end; ++i) hist[(keys[i] >> shift) & (PRIM_RADIX - 1)]++;
    for (int d = 0; d < PRIM_RADIX; ++d) table[d * chunks + c] = hist[d];
}

/* Move each (key, value) of the chunk to its slot, in order (stable). */
__kernel void Prim_radix_scatter(const __global uint *keys, const __global int *values,
                                 __global uint *keys_out, __global int *values_out,
                                 const int n, const int shift, const int chunk,
                                 const __global int *table, const int chunks) {
    int c = get_global_id(0);
    if (c >= chunks) return;
    int slot[PRIM_RADIX];
    for (int d = 0; d < PRIM_RADIX; ++d) slot[d] = table[d * chunks + c];
    int end = min(n, (c + 1) * chunk);
    for (int i = c * chunk; i < end; ++i) {
        uint key = keys[i];
        int at = slot[(key >> shift) & (PRIM_RADIX - 1)]++;
        keys_out[at] = key;
        values_out[at] = values[i];
    }
}

/* For sorted keys, [start[k], end[k]) is the run of key k; both arrays are
 * zero beforehand, so absent keys give empty runs. */
__kernel void Prim_group_ranges(const __global uint *keys, const int n, __global int *start,
                                __global int *end) {
    int i = get_global_id(0);
    if (i >= n) return;
    uint key = keys[i];
    if (i == 0 || keys[i - 1] != key) start[key] = i;
    if (i == n - 1 || keys[i + 1] != key) end[key] = i + 1;
}

/* out[i] = values[index[i]] for float4 rows. */
__kernel void Prim_gather_float4(const __global float4 *values, const __global int *index, const int n,
                                 __global float4 *out) {
    int i = get_global_id(0);
    if (i < n) out[i] = values[index[i]];
}

/* Each point with its index in w (int bits), as the point-tree builder takes them. */
__kernel void Prim_indexed_points(const __global float4 *points, const int n, __global float4 *out) {
    int i = get_global_id(0);
    if (i < n) out[i] = (float4)(points[i].xyz, as_float(i));
}
