/* Point kd-tree construction on the device [ZHWG08], breadth-first: every
 * kernel here handles all nodes (or chunks of points) of one tree level at
 * once; the host only loops over levels and reads one word of list sizes
 * per level.
 *
 * Large-node stage: a node's points are a contiguous segment of the working
 * array, processed in chunks of POINT_BUILD_CHUNK. Each level cuts off
 * empty space or splits at the spatial median of the cell's longest axis,
 * then partitions the segments stably. The host does not read the number
 * of chunks: it launches the chunk kernels over a bound (n_active + n /
 * POINT_BUILD_CHUNK) and they find the count on the device. Small-node
 * stage (<= POINT_BUILD_SMALL points): the small root's points are fixed;
 * a node is a bit mask over them, and the split is the candidate plane (a
 * point coordinate) of least VVH cost. Output stage: subtree
 * sizes and photon sums bottom-up, preorder addresses top-down, then the
 * traversal nodes, node payloads and points in leaf order. */
#include "device/axis.h"
#include "accel/point_tree.h"

/* axis value of a node whose points are all identical: split by count */
#define BUILD_COUNT_SPLIT 4

/* Side of a point of a large node; rank = its position in the node's segment. */
inline bool PointBuild_goes_left(const BuildNode *nd, float4 p, int rank) {
    if (nd->axis == BUILD_COUNT_SPLIT) return rank < nd->count / 2;
    return Axis_of(p, nd->axis) < nd->split;
}

/* Store l and r, the children of node id at depth `depth`, at c0 and c0 + 1
 * as unsplit nodes one level deeper. */
inline void PointBuild_store_children(__global BuildNode *nodes, int id, int c0, BuildNode l, BuildNode r, int depth) {
    l.left = r.left = -1;
    l.axis = r.axis = 0;
    l.split = r.split = 0.0f;
    l.depth = r.depth = depth + 1;
    nodes[c0] = l;
    nodes[c0 + 1] = r;
    nodes[id].left = c0;
}

/* ---- large-node stage ---------------------------------------------------- */

/* Chunks of this level: chunk_end is the inclusive scan of the active
 * nodes' chunk counts. */
inline int PointBuild_chunk_total(const __global int *chunk_end, int n_active) {
    return chunk_end[n_active - 1];
}

/* Number of chunks of each active node. */
__kernel void PointBuild_chunk_counts(const __global int *active, const __global BuildNode *nodes,
                                 __global int *counts, const int n_active) {
    int j = get_global_id(0);
    if (j >= n_active) return;
    counts[j] = (nodes[active[j]].count + POINT_BUILD_CHUNK - 1) / POINT_BUILD_CHUNK;
}

/* The chunks of each active node; chunk_end is the inclusive scan of counts. */
__kernel void PointBuild_chunks(const __global int *active, const __global BuildNode *nodes,
                           const __global int *chunk_end, __global Chunk *chunks,
                           const int n_active) {
    int j = get_global_id(0);
    if (j >= n_active) return;
    BuildNode nd = nodes[active[j]];
    int first = j > 0 ? chunk_end[j - 1] : 0;
    int n = chunk_end[j] - first;
    for (int c = 0; c < n; ++c) {
        Chunk ch;
        ch.slot = j;
        ch.start = nd.start + c * POINT_BUILD_CHUNK;
        ch.count = min(POINT_BUILD_CHUNK, nd.count - c * POINT_BUILD_CHUNK);
        ch.rank = c;
        chunks[first + c] = ch;
    }
}

/* Bounding box of each chunk's points. */
__kernel void PointBuild_chunk_bounds(const __global Chunk *chunks, const __global float4 *pts,
                                 __global float4 *chunk_lo, __global float4 *chunk_hi,
                                 const __global int *chunk_end, const int n_active) {
    int c = get_global_id(0);
    if (c >= PointBuild_chunk_total(chunk_end, n_active)) return;
    Chunk ch = chunks[c];
    float4 lo = (float4)(INFINITY), hi = (float4)(-INFINITY);
    for (int i = 0; i < ch.count; ++i) {
        float4 p = pts[ch.start + i];
        lo = fmin(lo, p);
        hi = fmax(hi, p);
    }
    chunk_lo[c] = lo;
    chunk_hi[c] = hi;
}

/* Per active node: reduce its chunks to the tight box, then choose an
 * empty-space cut (the side with the largest empty fraction of the cell,
 * when over empty_ratio) or a spatial-median split of the cell's longest
 * axis. A cut leaves the points on one side and nothing on the other. */
__kernel void PointBuild_large_decide(const __global int *active, __global BuildNode *nodes,
                                 const __global int *chunk_end, const __global float4 *chunk_lo,
                                 const __global float4 *chunk_hi, const float empty_ratio,
                                 const int n_active) {
    int j = get_global_id(0);
    if (j >= n_active) return;
    int id = active[j];
    BuildNode nd = nodes[id];
    int first = j > 0 ? chunk_end[j - 1] : 0;
    float4 tlo = (float4)(INFINITY), thi = (float4)(-INFINITY);
    for (int c = first; c < chunk_end[j]; ++c) {
        tlo = fmin(tlo, chunk_lo[c]);
        thi = fmax(thi, chunk_hi[c]);
    }
    /* the root arrives with an empty cell: it is its points' box */
    if (!(nd.lo.x <= nd.hi.x)) {
        nd.lo = tlo;
        nd.hi = thi;
        nodes[id] = nd;
    }
    float4 ext = nd.hi - nd.lo;
    float4 text = thi - tlo;

    /* empty-space cut */
    float best = empty_ratio;
    int cut_axis = -1;
    bool cut_low = false;
    for (int a = 0; a < 3; ++a) {
        float e = Axis_of(ext, a);
        if (!(e > 0.0f)) continue;
        /* measured to where each cut would put the plane */
        float low = (Axis_of(tlo, a) - Axis_of(nd.lo, a)) / e;
        float high = (Axis_of(nd.hi, a) - nextafter(Axis_of(thi, a), INFINITY)) / e;
        if (low > best) { best = low; cut_axis = a; cut_low = true; }
        if (high > best) { best = high; cut_axis = a; cut_low = false; }
    }
    if (cut_axis >= 0) {
        nd.axis = cut_axis;
        /* low cut: every point is >= tlo goes right; high cut: every point is
         * < the next float above thi goes left */
        nd.split = cut_low ? Axis_of(tlo, cut_axis) : nextafter(Axis_of(thi, cut_axis), INFINITY);
        nodes[id] = nd;
        return;
    }

    /* median split of the longest cell axis that the points actually span */
    int a = 0;
    float longest = -1.0f;
    for (int k = 0; k < 3; ++k) {
        if (Axis_of(text, k) > 0.0f && Axis_of(ext, k) > longest) {
            longest = Axis_of(ext, k);
            a = k;
        }
    }
    if (longest < 0.0f) {
        /* all points identical */
        nd.axis = BUILD_COUNT_SPLIT;
        nd.split = tlo.x;
        nodes[id] = nd;
        return;
    }
    float t0 = Axis_of(tlo, a), t1 = Axis_of(thi, a);
    float split = 0.5f * (Axis_of(nd.lo, a) + Axis_of(nd.hi, a));
    if (!(split > t0 && split <= t1)) split = 0.5f * (t0 + t1);
    if (!(split > t0)) split = t1; /* t0 and t1 adjacent floats */
    nd.axis = a;
    nd.split = split;
    nodes[id] = nd;
}

/* Points of each chunk that go to the left child; 0 past the last chunk,
 * up to the bound, so that the bound's prefix sums hold. */
__kernel void PointBuild_chunk_count_left(const __global Chunk *chunks, const __global int *active,
                                     const __global BuildNode *nodes, const __global float4 *pts,
                                     __global int *chunk_left, const __global int *chunk_end,
                                     const int n_active, const int bound) {
    int c = get_global_id(0);
    if (c >= bound) return;
    if (c >= PointBuild_chunk_total(chunk_end, n_active)) {
        chunk_left[c] = 0;
        return;
    }
    Chunk ch = chunks[c];
    BuildNode nd = nodes[active[ch.slot]];
    int n = 0;
    for (int i = 0; i < ch.count; ++i)
        n += PointBuild_goes_left(&nd, pts[ch.start + i], ch.rank * POINT_BUILD_CHUNK + i) ? 1 : 0;
    chunk_left[c] = n;
}

/* Class of a new node as two counters in one long: low word 1 when it is
 * large (split again), high word 1 when it is a small root; 0 for a leaf. */
inline long PointBuild_class_flags(int count, int depth, int max_depth) {
    if (depth >= max_depth) return 0;
    if (count > POINT_BUILD_SMALL) return 1;
    return count >= 2 ? ((long)1 << 32) : 0;
}

/* Create both children of every active node at child_base + 2 j, with
 * their classes (PointBuild_class_flags); left_end is the inclusive scan of
 * the chunks' left counts. */
__kernel void PointBuild_large_split(const __global int *active, __global BuildNode *nodes,
                                const __global int *chunk_end, const __global int *left_end,
                                const int child_base, const int max_depth, __global long *classes,
                                const int n_active) {
    int j = get_global_id(0);
    if (j >= n_active) return;
    int id = active[j];
    BuildNode nd = nodes[id];
    int first = j > 0 ? chunk_end[j - 1] : 0;
    int n_left = left_end[chunk_end[j] - 1] - (first > 0 ? left_end[first - 1] : 0);
    BuildNode l, r;
    l.lo = r.lo = nd.lo;
    l.hi = r.hi = nd.hi;
    if (nd.axis != BUILD_COUNT_SPLIT) {
        l.hi = Axis_with(l.hi, nd.axis, nd.split);
        r.lo = Axis_with(r.lo, nd.axis, nd.split);
    }
    l.start = nd.start;
    l.count = n_left;
    r.start = nd.start + n_left;
    r.count = nd.count - n_left;
    l.mask = r.mask = 0u;
    l.root = r.root = -1;
    PointBuild_store_children(nodes, id, child_base + 2 * j, l, r, nd.depth);
    classes[2 * j] = PointBuild_class_flags(l.count, nd.depth + 1, max_depth);
    classes[2 * j + 1] = PointBuild_class_flags(r.count, nd.depth + 1, max_depth);
}

/* Stable partition of each chunk's points into its node's two children. */
__kernel void PointBuild_chunk_scatter(const __global Chunk *chunks, const __global int *active,
                                  const __global BuildNode *nodes, const __global float4 *pts,
                                  __global float4 *out, const __global int *chunk_left,
                                  const __global int *left_end, const __global int *chunk_end,
                                  const int n_active) {
    int c = get_global_id(0);
    if (c >= PointBuild_chunk_total(chunk_end, n_active)) return;
    Chunk ch = chunks[c];
    BuildNode nd = nodes[active[ch.slot]];
    int first = c - ch.rank;
    int left_before = (left_end[c] - chunk_left[c]) - (first > 0 ? left_end[first - 1] : 0);
    int right_before = ch.rank * POINT_BUILD_CHUNK - left_before;
    int n_left = nodes[nd.left].count;
    for (int i = 0; i < ch.count; ++i) {
        float4 p = pts[ch.start + i];
        if (PointBuild_goes_left(&nd, p, ch.rank * POINT_BUILD_CHUNK + i))
            out[nd.start + left_before++] = p;
        else
            out[nd.start + n_left + right_before++] = p;
    }
}

/* Copy the partitioned chunks back to the working array. */
__kernel void PointBuild_chunk_copy(const __global Chunk *chunks, const __global float4 *from,
                               __global float4 *to, const __global int *chunk_end, const int n_active) {
    int c = get_global_id(0);
    if (c >= PointBuild_chunk_total(chunk_end, n_active)) return;
    Chunk ch = chunks[c];
    for (int i = 0; i < ch.count; ++i) to[ch.start + i] = from[ch.start + i];
}

/* The new nodes (base + i) into the next level's large list and the small
 * roots' list, in order, at the exclusive prefix sums of their class flags. */
__kernel void PointBuild_lists(const __global long *classes, const __global long *scanned, const int base,
                               const int n, __global int *large, __global int *small) {
    int i = get_global_id(0);
    if (i >= n) return;
    long c = classes[i], at = scanned[i];
    if (c & 0xffffffffL) large[(int)(at & 0xffffffffL)] = base + i;
    if (c >> 32) small[(int)(at >> 32)] = base + i;
}

/* ---- small-node stage ---------------------------------------------------- */

/* Per small root: tight box as its cell, full mask, the left-side mask of
 * every candidate plane (3 axes x its points; ties ordered by index), and
 * an estimate of the radius holding k_hint points, from the box's measure
 * in as many dimensions as the points spread (radius < 0: no estimate). */
__kernel void PointBuild_small_roots(const __global int *roots, __global BuildNode *nodes,
                                const __global float4 *pts, __global uint *masks,
                                __global float *radius, const float k_hint, const int n_roots) {
    int r = get_global_id(0);
    if (r >= n_roots) return;
    int id = roots[r];
    BuildNode nd = nodes[id];
    int n = nd.count;
    float4 lo = (float4)(INFINITY), hi = (float4)(-INFINITY);
    for (int i = 0; i < n; ++i) {
        float4 p = pts[nd.start + i];
        lo = fmin(lo, p);
        hi = fmax(hi, p);
    }
    nd.lo = lo;
    nd.hi = hi;
    nd.root = r;
    nd.mask = n >= POINT_BUILD_SMALL ? 0xffffffffu : ((1u << n) - 1u);
    nodes[id] = nd;
    /* along each axis: the points sorted by coordinate, ties by index (a
     * stable insertion sort), then each one's mask is the points up to it
     * in that order */
    float c[POINT_BUILD_SMALL];
    int order[POINT_BUILD_SMALL];
    for (int a = 0; a < 3; ++a) {
        for (int i = 0; i < n; ++i) {
            float v = Axis_of(pts[nd.start + i], a);
            int k = i;
            while (k > 0 && c[k - 1] > v) {
                c[k] = c[k - 1];
                order[k] = order[k - 1];
                k--;
            }
            c[k] = v;
            order[k] = i;
        }
        uint m = 0u;
        for (int k = 0; k < n; ++k) {
            m |= 1u << order[k];
            masks[(size_t)r * 3 * POINT_BUILD_SMALL + a * POINT_BUILD_SMALL + order[k]] = m;
        }
    }
    /* radius estimate: k_hint points in a ball of the local dimension */
    float4 e = hi - lo;
    float e_max = fmax(fmax(e.x, e.y), e.z);
    int dims = 0;
    float measure = 1.0f;
    for (int a = 0; a < 3; ++a) {
        float ea = Axis_of(e, a);
        if (ea > 0.1f * e_max && ea > 0.0f) {
            dims++;
            measure *= ea;
        }
    }
    float est = -1.0f;
    if (dims > 0) {
        float unit_ball = dims == 1 ? 2.0f : (dims == 2 ? 3.14159265f : 4.18879020f);
        est = pow(k_hint * measure / ((float)n * unit_ball), 1.0f / (float)dims);
    }
    radius[r] = est;
}

/* Per active small node: the candidate plane of least VVH cost
 *   C_t + (n_L (V_L grown by R) + n_R (V_R grown by R)) / (V grown by R);
 * boxes differ only along the split axis, so the volumes reduce to lengths.
 * The node splits when the cost is below its point count (the cost of
 * scanning it as a leaf); cand = 1 + the chosen point's index, 0 for a leaf. */
__kernel void PointBuild_small_decide(const __global int *active, __global BuildNode *nodes,
                                 const __global float4 *pts, const __global uint *masks,
                                 const float radius, const float cost_traverse,
                                 const int max_depth, __global int *split_flag,
                                 __global int *cand, const int n_active) {
    int j = get_global_id(0);
    if (j >= n_active) return;
    int id = active[j];
    BuildNode nd = nodes[id];
    int n = popcount(nd.mask);
    float best = (float)n;
    int best_a = -1, best_j = -1;
    if (n >= 2 && nd.depth < max_depth) {
        for (int a = 0; a < 3; ++a) {
            float lo = Axis_of(nd.lo, a), hi = Axis_of(nd.hi, a);
            float denom = hi - lo + 2.0f * radius;
            if (!(denom > 0.0f)) continue;
            float inv = 1.0f / denom;
            uint rest = nd.mask;
            while (rest) {
                int k = 31 - clz(rest);
                rest &= ~(1u << k);
                uint lm = masks[(size_t)nd.root * 3 * POINT_BUILD_SMALL + a * POINT_BUILD_SMALL + k] & nd.mask;
                int nl = popcount(lm);
                int nr = n - nl;
                if (nr == 0) continue;
                float s = Axis_of(pts[nd.start + k], a);
                float cost = cost_traverse +
                             (nl * (s - lo + 2.0f * radius) + nr * (hi - s + 2.0f * radius)) * inv;
                if (cost < best) {
                    best = cost;
                    best_a = a;
                    best_j = k;
                }
            }
        }
    }
    if (best_a >= 0) {
        nd.axis = best_a;
        nd.split = Axis_of(pts[nd.start + best_j], best_a);
        nodes[id] = nd;
    }
    split_flag[j] = best_a >= 0 ? 1 : 0;
    cand[j] = best_j;
}

/* Children of the splitting small nodes (indices into the active list) at
 * child_base + 2 j: the masks of both sides and the cell cut at the plane.
 * Every child is active on the next level (small_decide makes leaves). */
__kernel void PointBuild_small_split(const __global int *splitting, const __global int *active,
                                __global BuildNode *nodes, const __global int *cand,
                                const __global uint *masks, const int child_base,
                                __global int *next_active, const int n_split) {
    int j = get_global_id(0);
    if (j >= n_split) return;
    int slot = splitting[j];
    int id = active[slot];
    BuildNode nd = nodes[id];
    uint lm = masks[(size_t)nd.root * 3 * POINT_BUILD_SMALL + nd.axis * POINT_BUILD_SMALL + cand[slot]] & nd.mask;
    BuildNode l = nd, r = nd;
    l.mask = lm;
    r.mask = nd.mask & ~lm;
    l.count = popcount(l.mask);
    r.count = popcount(r.mask);
    l.hi = Axis_with(nd.hi, nd.axis, nd.split);
    r.lo = Axis_with(nd.lo, nd.axis, nd.split);
    PointBuild_store_children(nodes, id, child_base + 2 * j, l, r, nd.depth);
    next_active[2 * j] = child_base + 2 * j;
    next_active[2 * j + 1] = child_base + 2 * j + 1;
}

/* ---- output stage -------------------------------------------------------- */

/* i-th point of a leaf: its place in the working array. */
inline int PointBuild_leaf_point(const BuildNode *nd, uint *rest, int i) {
    if (nd->root < 0) return nd->start + i;
    int k = 31 - clz(*rest);
    *rest &= ~(1u << k);
    return nd->start + k;
}

/* Bottom-up over one batch of nodes (children live in later batches):
 * subtree size and photon sums, from the points at a leaf and from the
 * two children otherwise. */
__kernel void PointBuild_sums(const __global BuildNode *nodes, const __global float4 *pts,
                         const __global float4 *power, const __global float4 *dir,
                         const __global float4 *normal, const int has_photons,
                         __global int *size, __global BuildSums *sums, const int base,
                         const int n) {
    int i = get_global_id(0);
    if (i >= n) return;
    int id = base + i;
    BuildNode nd = nodes[id];
    BuildSums s;
    if (nd.left >= 0) {
        BuildSums a = sums[nd.left], b = sums[nd.left + 1];
        s.lo = fmin(a.lo, b.lo);
        s.hi = fmax(a.hi, b.hi);
        s.power = a.power + b.power;
        s.normal = a.normal + b.normal;
        s.position = a.position + b.position;
        for (int c = 0; c < 3; ++c) s.moment[c] = a.moment[c] + b.moment[c];
        size[id] = 1 + size[nd.left] + size[nd.left + 1];
        sums[id] = s;
        return;
    }
    s.lo = (float4)(INFINITY);
    s.hi = (float4)(-INFINITY);
    s.power = s.normal = s.position = (float4)(0.0f);
    for (int c = 0; c < 3; ++c) s.moment[c] = (float4)(0.0f);
    uint rest = nd.mask;
    for (int k = 0; k < nd.count; ++k) {
        float4 p = pts[PointBuild_leaf_point(&nd, &rest, k)];
        s.lo = fmin(s.lo, p);
        s.hi = fmax(s.hi, p);
        s.position += (float4)(p.xyz, 0.0f);
        if (has_photons) {
            int o = as_int(p.w);
            float4 phi = power[o], w = dir[o];
            s.power += phi;
            s.normal += normal[o];
            s.moment[0] += phi.x * w;
            s.moment[1] += phi.y * w;
            s.moment[2] += phi.z * w;
        }
    }
    size[id] = 1;
    sums[id] = s;
}

/* Top-down over one batch: preorder address and first point of both
 * children of every inner node (the root's are 0, set by the host). */
__kernel void PointBuild_preorder(const __global BuildNode *nodes, const __global int *size,
                             __global int *addr, __global int *first, const int base,
                             const int n) {
    int i = get_global_id(0);
    if (i >= n) return;
    int id = base + i;
    BuildNode nd = nodes[id];
    if (nd.left < 0) return;
    addr[nd.left] = addr[id] + 1;
    addr[nd.left + 1] = addr[id] + 1 + size[nd.left];
    first[nd.left] = first[id];
    first[nd.left + 1] = first[id] + nodes[nd.left].count;
}

/* Every node to its preorder slot: the traversal node, the payload with
 * E~_p = max(0, n_p . sum_i w_i Phi_i) / r_p^2 (r_p the largest extent of the
 * tight box, at least `radius`), and a leaf's points (and photon
 * attributes) to leaf order. */
__kernel void PointBuild_emit(const __global BuildNode *nodes, const __global BuildSums *sums,
                         const __global int *addr, const __global int *first,
                         const __global float4 *pts, const __global float4 *power,
                         const __global float4 *dir, const __global float4 *normal,
                         const int has_photons, const float radius, __global KdNode *out_nodes,
                         __global PointNode *out_info, __global float4 *out_pts,
                         __global float4 *out_power, __global float4 *out_dir,
                         __global float4 *out_normal, const int n) {
    int id = get_global_id(0);
    if (id >= n) return;
    BuildNode nd = nodes[id];
    BuildSums s = sums[id];
    int at = addr[id];
    int f = first[id];
    KdNode k;
    if (nd.left >= 0) {
        k.split = nd.split;
        k.axis = nd.axis == BUILD_COUNT_SPLIT ? 0 : nd.axis;
        k.child = addr[nd.left + 1];
        k.count = 0;
    } else {
        k.split = 0.0f;
        k.axis = KD_LEAF;
        k.child = f;
        k.count = nd.count;
        uint rest = nd.mask;
        for (int i = 0; i < nd.count; ++i) {
            float4 p = pts[PointBuild_leaf_point(&nd, &rest, i)];
            out_pts[f + i] = p;
            if (has_photons) {
                int o = as_int(p.w);
                out_power[f + i] = power[o];
                out_dir[f + i] = dir[o];
                out_normal[f + i] = normal[o];
            }
        }
    }
    out_nodes[at] = k;

    PointNode info;
    float3 ext = nd.count > 0 ? (s.hi - s.lo).xyz : (float3)(0.0f);
    float r_p = fmax(fmax(fmax(ext.x, ext.y), ext.z), radius);
    float len = length(s.normal.xyz);
    float3 n_p = len > 0.0f ? s.normal.xyz / len : (float3)(0.0f);
    float3 e = PointNode_irradiance(n_p, r_p, s.moment[0].xyz, s.moment[1].xyz, s.moment[2].xyz);
    info.lo = nd.count > 0 ? (float4)(s.lo.xyz, r_p) : (float4)(0.0f, 0.0f, 0.0f, r_p);
    info.hi = nd.count > 0 ? (float4)(s.hi.xyz, 0.0f) : (float4)(0.0f);
    info.power = (float4)(s.power.xyz, 0.0f);
    info.irradiance = (float4)(e, 0.0f);
    /* w: |mean photon normal|, 1 when every photon lies on one surface facing one way */
    info.normal = (float4)(n_p, nd.count > 0 ? len / (float)nd.count : 0.0f);
    info.mean = nd.count > 0 ? s.position / (float)nd.count : 0.5f * (info.lo + info.hi);
    info.mean.w = 0.0f;
    info.first = f;
    info.count = nd.count;
    info.depth = nd.depth;
    info.pad = 0;
    out_info[at] = info;
}
