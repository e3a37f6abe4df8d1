/* Breadth-first kd-tree construction over triangles [ZHWG08]. Each kernel
 * handles one list of nodes (or their elements) in parallel; the host
 * launches them level by level and reads back only counts.
 *
 * Element: a (triangle, node) pair with the triangle's bounds clipped to the
 *   node, as el_tri / el_lo / el_hi; a node's elements are contiguous.
 * Record: a node in creation order. rec_lo / rec_hi is its cell, rec_info is
 *   (axis or KD_LEAF, left record or leaf offset, right record or leaf
 *   size, depth), rec_split its plane. The output stage turns records into
 *   the preorder KdNode array (device/structs.h).
 * Large node: (element start, element count, record, depth | bad << 16)
 *   in an int4, with its cell beside it; "bad" counts the median splits
 *   just above it that made no progress (KdBuild_child_bad). Small node: (small root, record) and a 64-bit
 *   mask of the small root's elements it holds.
 *
 * Defines from the host: KD_CHUNK (elements per chunk, a power of two),
 * KD_SMALL (largest small node, at most 64), KD_EMPTY_RATIO (empty-space
 * cut threshold), KD_COST_TRAVERSE (SAH cost of a node step, in triangle
 * tests), KD_BAD_SPLITS (median splits in a row without progress allowed
 * before a large node becomes a leaf), KD_SAH_GROUP (work-group size of the SAH
 * search), KD_SAH_LANES (its work-items per node, a power of two
 * dividing KD_SAH_GROUP), KD_MAX_CHAIN (empty-space cuts a large node
 * makes in one level before its split: one a face of its cell), KD_RUN
 * (elements a work-item of the large stage's classification and scatter
 * takes in a row) and KD_PREFETCH_AHEAD (how many elements ahead in its run
 * the classification asks for a straddler's corners; 0: never). */
#include "device/launch.h"
#include "device/structs.h"
#include "accel/kdtree_clip.h"
#include "device/sort_small.h"

/* How a large node is divided (bits 2.. of its mode; bits 0..1: axis). The
 * "low" rule puts elements lying in the plane above it, "high" below. */
#define KD_SPLIT_MEDIAN 0 /* spatial median, high rule */
#define KD_CUT_LOW 1      /* empty space below the plane cut off, low rule */
#define KD_CUT_HIGH 2     /* empty space above the plane cut off, high rule */
#define KD_SPLIT_NONE 3   /* no plane splits it: the node becomes a leaf */

/* Where a child's elements go. */
#define KD_DEST_NONE 0
#define KD_DEST_LARGE 1
#define KD_DEST_SMALL 2
#define KD_DEST_LEAF 3

inline float KdBuild_area(float4 lo, float4 hi) {
    float4 d = hi - lo;
    return 2.0f * (d.x * d.y + d.y * d.z + d.z * d.x);
}

/* Depth and count of unpaid splits of a large node (its info.w). */
inline int KdBuild_depth(int4 info) { return info.w & 0xffff; }
inline int KdBuild_bad(int4 info) { return info.w >> 16; }

/* Whether a spatial-median split of a cell holding `total` elements into
 * children of `counts` pays by the SAH: C_t + (A_l n_l + A_r n_r) / A
 * below the leaf's n. A soup of triangles large against the cell and a
 * stack of triangles do not pay. */
inline bool KdBuild_pays(float4 lo, float4 hi, int axis, float plane, int2 counts, int total) {
    float area = KdBuild_area(lo, hi);
    if (!(area > 0.0f)) return true;
    float left = KdBuild_area(lo, Axis_with(hi, axis, plane));
    float right = KdBuild_area(Axis_with(lo, axis, plane), hi);
    return KD_COST_TRAVERSE + (left * (float)counts.x + right * (float)counts.y) / area < (float)total;
}

/* A child's count of median splits in a row that made no progress for it:
 * the split did not pay, or the child kept every element of its parent
 * while its sibling kept more than half (the cells around a fan's centre,
 * a stack of triangles). Any other median split starts it again from 0 (an
 * object over a floor: the object's side keeps all, the other only the
 * floor); empty-space cuts pass it on. */
inline int KdBuild_child_bad(int4 info, int mode, bool pays, int2 counts, int count) {
    if ((mode >> 2) != KD_SPLIT_MEDIAN) return KdBuild_bad(info);
    bool stuck = count >= info.y && 2 * min(counts.x, counts.y) > info.y;
    return (!pays || stuck) ? KdBuild_bad(info) + 1 : 0;
}

/* Sides of the plane an element with bounds [lo, hi] on the split axis
 * belongs to: bit 0 below, bit 1 above. Elements touching the plane from
 * one side stay on that side; flat ones in it follow the rule. */
inline int KdBuild_sides(float lo, float hi, float plane, bool low_rule) {
    bool below, above;
    if (low_rule) {
        below = lo < plane;
        above = hi > plane || lo >= plane;
    } else {
        below = lo < plane || hi <= plane;
        above = hi > plane;
    }
    return (below ? 1 : 0) | (above ? 2 : 0);
}

/* ---- setup -------------------------------------------------------------- */

/* One element per triangle, with the triangle's bounds. */
__kernel void KdBuild_init(const __global float4 *verts, const int n,
                           __global int *el_tri, __global float4 *el_lo,
                           __global float4 *el_hi) {
    int i = Launch_global_id();
    if (i >= n) return;
    float4 a = verts[3 * i], b = verts[3 * i + 1], c = verts[3 * i + 2];
    el_tri[i] = i;
    el_lo[i] = fmin(fmin(a, b), c);
    el_hi[i] = fmax(fmax(a, b), c);
}

/* ---- large-node stage --------------------------------------------------- */

/* Chunk -> node map: node i owns chunks chunk_base[i] .. + ceil(count/KD_CHUNK). */
inline void KdBuild_chunk_nodes_at(int i, const __global int4 *act_info, const __global int *chunk_base,
                                   __global int *chunk_node) {
    int chunks = (act_info[i].y + KD_CHUNK - 1) / KD_CHUNK;
    for (int k = 0; k < chunks; ++k) chunk_node[chunk_base[i] + k] = i;
}

__kernel void KdBuild_chunk_nodes(const __global int4 *act_info,
                                  const __global int *chunk_base, const int n,
                                  __global int *chunk_node) {
    int i = Launch_global_id();
    if (i < n) KdBuild_chunk_nodes_at(i, act_info, chunk_base, chunk_node);
}

/* The elements [*begin, *end) of chunk c and its node. */
inline int KdBuild_chunk_range(const __global int4 *act_info, const __global int *chunk_base,
                               const __global int *chunk_node, int c, int *begin, int *end) {
    int node = chunk_node[c];
    int4 info = act_info[node];
    *begin = info.x + (c - chunk_base[node]) * KD_CHUNK;
    *end = min(*begin + KD_CHUNK, info.x + info.y);
    return node;
}

/* Bounds of the elements lid, lid + size, ... of chunk c (in *lo, *hi),
 * each tagged with its node. */
inline void KdBuild_chunk_lane(int c, int lid, int size, const __global int4 *act_info,
                               const __global int *chunk_base, const __global int *chunk_node,
                               const __global float4 *el_lo, const __global float4 *el_hi, __global int *el_node,
                               float4 *lo, float4 *hi) {
    int begin, end;
    int node = KdBuild_chunk_range(act_info, chunk_base, chunk_node, c, &begin, &end);
    *lo = (float4)(INFINITY);
    *hi = (float4)(-INFINITY);
    for (int e = begin + lid; e < end; e += size) {
        *lo = fmin(*lo, el_lo[e]);
        *hi = fmax(*hi, el_hi[e]);
        el_node[e] = node;
    }
}

/* Bounds of each chunk's elements; also tags elements with their node.
 * KD_CHUNK_LANES work-items a chunk: one on a CPU (a loop, no barriers: a
 * group of mostly idle work-items and its barriers cost more there, most
 * chunks of the deeper levels holding a few elements), else a work-group
 * reduction (one group per chunk, power-of-two size up to KD_CHUNK). */
__kernel void KdBuild_chunk_bounds(const __global int4 *act_info,
                                   const __global int *chunk_base,
                                   const __global int *chunk_node,
                                   const __global float4 *el_lo,
                                   const __global float4 *el_hi,
                                   __global int *el_node,
                                   __global float4 *chunk_lo,
                                   __global float4 *chunk_hi, const __global int *chunk_total) {
    /* launched over a bound: the chunk count (the scan's total) is read here */
#if KD_CHUNK_LANES == 1
    int c = Launch_global_id(), lid = 0, size = 1;
    if (c >= chunk_total[0]) return;
#else
    __local float4 lo_s[KD_CHUNK], hi_s[KD_CHUNK];
    int c = Launch_group_id(), lid = get_local_id(0), size = get_local_size(0);
    if (c >= chunk_total[0]) return; /* the whole group */
#endif
    float4 lo, hi;
    KdBuild_chunk_lane(c, lid, size, act_info, chunk_base, chunk_node, el_lo, el_hi, el_node, &lo, &hi);
#if KD_CHUNK_LANES == 1
    chunk_lo[c] = lo;
    chunk_hi[c] = hi;
#else
    lo_s[lid] = lo;
    hi_s[lid] = hi;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int s = size / 2; s > 0; s >>= 1) {
        if (lid < s) {
            lo_s[lid] = fmin(lo_s[lid], lo_s[lid + s]);
            hi_s[lid] = fmax(hi_s[lid], hi_s[lid + s]);
        }
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (lid == 0) {
        chunk_lo[c] = lo_s[0];
        chunk_hi[c] = hi_s[0];
    }
#endif
}

/* The empty-space cut of a cell [cell_lo, cell_hi] whose elements lie in
 * [lo, hi] (within it): the side with the largest empty fraction beyond
 * KD_EMPTY_RATIO; KD_SPLIT_NONE where none is. */
inline int KdBuild_empty_cut(float4 lo, float4 hi, float4 cell_lo, float4 cell_hi, int *axis, float *plane) {
    float best = KD_EMPTY_RATIO;
    int kind = KD_SPLIT_NONE;
    for (int a = 0; a < 3; ++a) {
        float extent = Axis_of(cell_hi, a) - Axis_of(cell_lo, a);
        if (!(extent > 0.0f)) continue;
        float below = (Axis_of(lo, a) - Axis_of(cell_lo, a)) / extent;
        float above = (Axis_of(cell_hi, a) - Axis_of(hi, a)) / extent;
        if (below > best) {
            best = below;
            kind = KD_CUT_LOW;
            *axis = a;
            *plane = Axis_of(lo, a);
        }
        if (above > best) {
            best = above;
            kind = KD_CUT_HIGH;
            *axis = a;
            *plane = Axis_of(hi, a);
        }
    }
    return kind;
}

/* The cell [*lo, *hi] cut to one side of a plane: below it (side 0) or above. */
inline void KdBuild_child_cell(int axis, float plane, int side, float4 *lo, float4 *hi) {
    if (side == 0) *hi = Axis_with(*hi, axis, plane);
    else *lo = Axis_with(*lo, axis, plane);
}

/* The side a cut (mode) keeps: above a cut of the empty space below. */
inline int KdBuild_kept_side(int mode) { return (mode >> 2) == KD_CUT_LOW ? 1 : 0; }

/* The cell of what a cut (mode, plane) keeps of [*lo, *hi]. */
inline void KdBuild_cut_cell(int mode, float plane, float4 *lo, float4 *hi) {
    KdBuild_child_cell(mode & 3, plane, KdBuild_kept_side(mode), lo, hi);
}

/* Per node: its bounds from its chunks (segmented reduction, the chunks of
 * a node being contiguous), clipped to its cell; then the plane. A side
 * with more than KD_EMPTY_RATIO of the cell empty is cut off first;
 * otherwise the longest axis of the bounds is split at its middle.
 * Every element lies on the side a cut keeps, unchanged, so that side is
 * the same node with a smaller cell and one level deeper: where `chain`
 * allows and the depth limit leaves it a large node, the cut is kept in
 * the node's chain (chain_cut, node_chain[i] of them) and the decision
 * made again for the kept cell, in this level instead of the next (the
 * same tree, the node's elements passed over once); the last decision is
 * the node's plane and mode. `chain` is 0 where the level's children
 * could spend the element budget (whose leaves would then differ). */
inline void KdBuild_large_split_at(int i, const __global float4 *act_lo, const __global float4 *act_hi,
                                   const __global int4 *act_info, const __global int *chunk_base,
                                   const __global float4 *chunk_lo, const __global float4 *chunk_hi, int max_depth,
                                   int chain, __global float *node_split, __global int *node_mode,
                                   __global int *node_chain, __global int2 *chain_cut) {
    int first = chunk_base[i];
    int chunks = (act_info[i].y + KD_CHUNK - 1) / KD_CHUNK;
    float4 lo = (float4)(INFINITY), hi = (float4)(-INFINITY);
    for (int k = 0; k < chunks; ++k) {
        lo = fmin(lo, chunk_lo[first + k]);
        hi = fmax(hi, chunk_hi[first + k]);
    }
    float4 cell_lo = act_lo[i], cell_hi = act_hi[i];
    int depth = KdBuild_depth(act_info[i]), chained = 0, kind, axis = 0;
    float plane = 0.0f;
    while (true) {
        float4 blo = fmax(lo, cell_lo), bhi = fmin(hi, cell_hi);
        /* empty-space cut: the emptiest side beyond the threshold */
        kind = KdBuild_empty_cut(blo, bhi, cell_lo, cell_hi, &axis, &plane);
        /* spatial median of the longest axis whose middle lies strictly inside */
        if (kind == KD_SPLIT_NONE) {
            float longest = 0.0f;
            for (int a = 0; a < 3; ++a) {
                float l = Axis_of(blo, a), h = Axis_of(bhi, a);
                float mid = 0.5f * l + 0.5f * h;
                if (h - l > longest && l < mid && mid < h) {
                    longest = h - l;
                    kind = KD_SPLIT_MEDIAN;
                    axis = a;
                    plane = mid;
                }
            }
            break;
        }
        if (!chain || chained == KD_MAX_CHAIN || depth + chained + 1 >= max_depth) break;
        chain_cut[KD_MAX_CHAIN * i + chained] = (int2)(axis | (kind << 2), as_int(plane));
        KdBuild_cut_cell(axis | (kind << 2), plane, &cell_lo, &cell_hi);
        chained++;
    }
    node_chain[i] = chained;
    node_split[i] = plane;
    node_mode[i] = axis | (kind << 2);
}

/* Node i's cell and info at the end of its chain of cuts (depth past
 * them); returns the chain's length. */
inline int KdBuild_chain_end(int i, const __global float4 *act_lo, const __global float4 *act_hi,
                             const __global int4 *act_info, const __global int *node_chain,
                             const __global int2 *chain_cut, float4 *lo, float4 *hi, int4 *info) {
    *lo = act_lo[i];
    *hi = act_hi[i];
    *info = act_info[i];
    int n = node_chain[i];
    for (int j = 0; j < n; ++j) {
        int2 cut = chain_cut[KD_MAX_CHAIN * i + j];
        KdBuild_cut_cell(cut.x, as_float(cut.y), lo, hi);
    }
    info->w += n; /* the depth, in the low bits */
    return n;
}

__kernel void KdBuild_large_split(const __global float4 *act_lo,
                                  const __global float4 *act_hi,
                                  const __global int4 *act_info,
                                  const __global int *chunk_base,
                                  const __global float4 *chunk_lo,
                                  const __global float4 *chunk_hi, const int n,
                                  const int max_depth, const int chain,
                                  __global float *node_split,
                                  __global int *node_mode,
                                  __global int *node_chain,
                                  __global int2 *chain_cut) {
    int i = Launch_global_id();
    if (i < n)
        KdBuild_large_split_at(i, act_lo, act_hi, act_info, chunk_base, chunk_lo, chunk_hi, max_depth, chain,
                               node_split, node_mode, node_chain, chain_cut);
}

/* KdBuild_sides of box [lo, hi] against a split node's plane: on the
 * node's axis, by the rule of its mode (mode & 3 the axis, mode >> 2 how
 * the node is divided). */
inline int KdBuild_box_sides(float4 lo, float4 hi, int mode, float plane) {
    int axis = mode & 3;
    return KdBuild_sides(Axis_of(lo, axis), Axis_of(hi, axis), plane, (mode >> 2) == KD_CUT_LOW);
}

/* Per element: the sides of its node's plane it goes to (packed as
 * below | above << 32 for the scan; also returned) and its bounds on each
 * side. A straddling triangle is clipped to its element's box once, that
 * polygon to each side of the plane widened by eps, and the triangle
 * dropped from a side it does not reach. Elements of an unsplit node all
 * go "below", to the node's own leaf. */
inline long KdBuild_large_classify_at(int e, const __global float4 *verts, const __global int *el_tri,
                                      const __global float4 *el_lo, const __global float4 *el_hi,
                                      const __global int *el_node, const __global float *node_split,
                                      const __global int *node_mode, float eps, __global long *flags,
                                      __global float4 *below_lo, __global float4 *below_hi,
                                      __global float4 *above_lo, __global float4 *above_hi) {
    int node = el_node[e];
    int mode = node_mode[node];
    int axis = mode & 3, kind = mode >> 2;
    float4 lo = el_lo[e], hi = el_hi[e];
    below_lo[e] = above_lo[e] = lo;
    below_hi[e] = above_hi[e] = hi;
    if (kind == KD_SPLIT_NONE) {
        flags[e] = 1;
        return 1;
    }
    float plane = node_split[node];
    int sides = KdBuild_box_sides(lo, hi, mode, plane);
    if (sides == 3) {
        int t = el_tri[e];
        float4 v0 = verts[3 * t], v1 = verts[3 * t + 1], v2 = verts[3 * t + 2];
        float4 widen = (float4)(eps, eps, eps, 0.0f);
        float4 box_hi = Axis_with(hi, axis, plane + eps);
        float4 box_lo = Axis_with(lo, axis, plane - eps);
        float4 clo, chi, cell[KD_CLIP_MAX + 1];
        int corners = KdClip_triangle(v0, v1, v2, lo, hi, cell);
        int kept = 0;
        if (KdClip_side_bounds(cell, corners, axis, plane + eps, -1.0f, &clo, &chi)) {
            below_lo[e] = fmax(clo - widen, lo);
            below_hi[e] = fmin(chi + widen, box_hi);
            kept |= 1;
        }
        if (KdClip_side_bounds(cell, corners, axis, plane - eps, 1.0f, &clo, &chi)) {
            above_lo[e] = fmax(clo - widen, box_lo);
            above_hi[e] = fmin(chi + widen, hi);
            kept |= 2;
        }
        if (kept == 0) { /* only if rounding lost it: keep it on both sides */
            below_hi[e] = box_hi;
            above_lo[e] = box_lo;
            kept = 3;
        }
        sides = kept;
    }
    long flag = (long)(sides & 1) | ((long)(sides >> 1) << 32);
    flags[e] = flag;
    return flag;
}

/* Asks for element e's triangle corners if e straddles its node's plane,
 * KD_PREFETCH_AHEAD elements before e's turn in the run, so that they are
 * in the caches when e is clipped: a straddler's triangle is rarely near
 * the last one's in memory, and its clipping otherwise waits on the load. */
inline void KdBuild_prefetch_straddler(int e, const __global float4 *verts, const __global int *el_tri,
                                       const __global float4 *el_lo, const __global float4 *el_hi,
                                       const __global int *el_node, const __global float *node_split,
                                       const __global int *node_mode) {
    int node = el_node[e];
    int mode = node_mode[node];
    if ((mode >> 2) != KD_SPLIT_NONE && KdBuild_box_sides(el_lo[e], el_hi[e], mode, node_split[node]) == 3)
        prefetch(verts + 3 * el_tri[e], 3);
}

__kernel void KdBuild_large_classify(const __global float4 *verts,
                                     const __global int *el_tri,
                                     const __global float4 *el_lo,
                                     const __global float4 *el_hi,
                                     const __global int *el_node,
                                     const __global float *node_split,
                                     const __global int *node_mode,
                                     const int n, const float eps,
                                     __global long *flags, __global long *run_sums,
                                     __global float4 *below_lo,
                                     __global float4 *below_hi,
                                     __global float4 *above_lo,
                                     __global float4 *above_hi) {
    /* KD_RUN elements in a row (on a CPU the corners asked for ahead are then
     * for this core's own later elements, and the runtime's cost per
     * work-item is paid once a run; 636k triangles: the large stage 163 ->
     * 137 ms); the run's flags are summed for the scan (KdBuild_flag_prefix) */
    int first = Launch_global_id() * KD_RUN, end = min(n, first + KD_RUN);
    long sum = 0;
    for (int e = first; e < end; ++e) {
#if KD_PREFETCH_AHEAD > 0
        if (e + KD_PREFETCH_AHEAD < n)
            KdBuild_prefetch_straddler(e + KD_PREFETCH_AHEAD, verts, el_tri, el_lo, el_hi, el_node, node_split,
                                       node_mode);
#endif
        sum += KdBuild_large_classify_at(e, verts, el_tri, el_lo, el_hi, el_node, node_split, node_mode, eps, flags,
                                         below_lo, below_hi, above_lo, above_hi);
    }
    if (first < n) run_sums[Launch_global_id()] = sum;
}

/* The sum of the flags of the elements before e (of n): the exclusive scan
 * of the runs' sums (run_scan; KD_RUN elements a run) at e's run, plus e's
 * predecessors in its run; total (the sum of all) at e = n. */
inline long KdBuild_flag_prefix(int e, int n, const __global long *flags, const __global long *run_scan,
                                const __global long *total) {
    if (e >= n) return total[0];
    long sum = run_scan[e / KD_RUN];
    for (int k = e - e % KD_RUN; k < e; ++k) sum += flags[k];
    return sum;
}

/* Whether a large child of node `info` becomes a leaf: at the depth limit,
 * when the level's element budget is spent (force_leaf), or past
 * KD_BAD_SPLITS median splits in a row without progress (`bad`). */
inline bool KdBuild_large_leaf(int4 info, int bad, int max_depth, int force_leaf) {
    return KdBuild_depth(info) + 1 >= max_depth || force_leaf || bad > KD_BAD_SPLITS;
}

/* Whether a median split of cell [lo, hi] pays (see KdBuild_pays); cuts always do. */
inline bool KdBuild_split_pays(float4 lo, float4 hi, int mode, float plane, int2 counts, int total) {
    return (mode >> 2) != KD_SPLIT_MEDIAN || KdBuild_pays(lo, hi, mode & 3, plane, counts, total);
}

/* Per node: the element counts of its two children (from the scan of the
 * element flags' runs, KdBuild_flag_prefix), each child's class, and the
 * node's contribution to the level's counters: (large elements, small
 * elements, leaf elements, large nodes, small roots, new records, 0, 0).
 * A child is an empty leaf when it has no element, a small root with at
 * most KD_SMALL, a leaf by KdBuild_large_leaf, else a large node. The node
 * is taken at the end of its chain of cuts, each of which adds two
 * records. */
inline void KdBuild_large_children_at(int i, const __global float4 *act_lo, const __global float4 *act_hi,
                                      const __global int4 *act_info, const __global float *node_split,
                                      const __global int *node_mode, const __global int *node_chain,
                                      const __global int2 *chain_cut, const __global long *flags,
                                      const __global long *run_scan, const __global long *flag_total, int n_el,
                                      int max_depth, int force_leaf, __global int2 *node_counts,
                                      __global int8 *counters) {
    float4 cell_lo, cell_hi;
    int4 info;
    int chained = KdBuild_chain_end(i, act_lo, act_hi, act_info, node_chain, chain_cut, &cell_lo, &cell_hi, &info);
    int end = info.x + info.y;
    long sum = KdBuild_flag_prefix(end, n_el, flags, run_scan, flag_total) -
               KdBuild_flag_prefix(info.x, n_el, flags, run_scan, flag_total);
    int2 counts = (int2)((int)(sum & 0xffffffffL), (int)(sum >> 32));
    node_counts[i] = counts;
    int8 c = (int8)(0);
    c.s5 = 2 * chained;
    int mode = node_mode[i];
    if ((mode >> 2) == KD_SPLIT_NONE) {
        c.s2 = counts.x;
    } else {
        bool pays = KdBuild_split_pays(cell_lo, cell_hi, mode, node_split[i], counts, info.y);
        c.s5 += 2;
        for (int side = 0; side < 2; ++side) {
            int count = side == 0 ? counts.x : counts.y;
            if (count == 0) continue;
            if (count <= KD_SMALL) {
                c.s1 += count;
                c.s4 += 1;
            } else if (KdBuild_large_leaf(info, KdBuild_child_bad(info, mode, pays, counts, count), max_depth, force_leaf)) {
                c.s2 += count;
            } else {
                c.s0 += count;
                c.s3 += 1;
            }
        }
    }
    counters[i] = c;
}

__kernel void KdBuild_large_children(const __global float4 *act_lo,
                                     const __global float4 *act_hi,
                                     const __global int4 *act_info,
                                     const __global float *node_split,
                                     const __global int *node_mode,
                                     const __global int *node_chain,
                                     const __global int2 *chain_cut,
                                     const __global long *flags,
                                     const __global long *run_scan,
                                     const __global long *flag_total,
                                     const int n_el, const int n,
                                     const int max_depth, const int force_leaf,
                                     __global int2 *node_counts,
                                     __global int8 *counters) {
    int i = Launch_global_id();
    if (i < n)
        KdBuild_large_children_at(i, act_lo, act_hi, act_info, node_split, node_mode, node_chain, chain_cut, flags,
                                  run_scan, flag_total, n_el, max_depth, force_leaf, node_counts, counters);
}

/* Per node: writes the records of its chain of cuts (each an inner node
 * with an empty leaf and the kept part, which the next cut or the last
 * decision divides), its own record, its children's records, cells and
 * depth, the next level's large nodes and the new small roots, and where
 * each child's elements go (dest: kind below, base below, kind above, base
 * above). Bases are the exclusive scan of the counters plus the level's
 * offsets into the growing arrays. */
inline void KdBuild_large_emit_at(
    int i, const __global float4 *act_lo, const __global float4 *act_hi, const __global int4 *act_info,
    const __global float *node_split, const __global int *node_mode, const __global int *node_chain,
    const __global int2 *chain_cut, const __global int2 *node_counts,
    const __global int8 *counter_scan, int max_depth, int force_leaf, int rec_base, int root_base, int small_el_base,
    int leaf_base, __global float4 *rec_lo, __global float4 *rec_hi, __global int4 *rec_info, __global float *rec_split,
    __global float4 *next_lo, __global float4 *next_hi, __global int4 *next_info, __global int4 *small_roots,
    __global int4 *node_dest) {
    int4 info = act_info[i];
    int8 base = counter_scan[i];
    float4 cell_lo = act_lo[i], cell_hi = act_hi[i];
    int depth = KdBuild_depth(info);
    for (int j = 0; j < node_chain[i]; ++j, ++depth) {
        int2 cut = chain_cut[KD_MAX_CHAIN * i + j];
        int left = rec_base + base.s5;
        base.s5 += 2;
        rec_info[info.z] = (int4)(cut.x & 3, left, left + 1, depth);
        rec_split[info.z] = as_float(cut.y);
        for (int side = 0; side < 2; ++side) {
            float4 lo = cell_lo, hi = cell_hi;
            KdBuild_child_cell(cut.x & 3, as_float(cut.y), side, &lo, &hi);
            rec_lo[left + side] = lo;
            rec_hi[left + side] = hi;
            rec_info[left + side] = (int4)(KD_LEAF, 0, 0, depth + 1);
        }
        KdBuild_cut_cell(cut.x, as_float(cut.y), &cell_lo, &cell_hi);
        info.z = left + KdBuild_kept_side(cut.x);
    }
    info.w = depth | (KdBuild_bad(info) << 16);
    int mode = node_mode[i];
    int axis = mode & 3;
    if ((mode >> 2) == KD_SPLIT_NONE) {
        rec_info[info.z] = (int4)(KD_LEAF, leaf_base + base.s2, info.y, depth);
        node_dest[i] = (int4)(KD_DEST_LEAF, leaf_base + base.s2, KD_DEST_NONE, 0);
        return;
    }
    float plane = node_split[i];
    int2 counts = node_counts[i];
    bool pays = KdBuild_split_pays(cell_lo, cell_hi, mode, plane, counts, info.y);
    int left = rec_base + base.s5;
    rec_info[info.z] = (int4)(axis, left, left + 1, depth);
    rec_split[info.z] = plane;
    int dest[4];
    for (int side = 0; side < 2; ++side) {
        int child = left + side;
        int count = side == 0 ? counts.x : counts.y;
        float4 lo = cell_lo, hi = cell_hi;
        KdBuild_child_cell(axis, plane, side, &lo, &hi);
        rec_lo[child] = lo;
        rec_hi[child] = hi;
        rec_info[child] = (int4)(KD_LEAF, 0, 0, depth + 1);
        int kind = KD_DEST_NONE, at = 0;
        int bad = KdBuild_child_bad(info, mode, pays, counts, count);
        if (count == 0) {
            /* an empty leaf */
        } else if (count <= KD_SMALL) {
            kind = KD_DEST_SMALL;
            at = small_el_base + base.s1;
            small_roots[root_base + base.s4] = (int4)(at, count, child, 0);
            base.s1 += count;
            base.s4 += 1;
        } else if (KdBuild_large_leaf(info, bad, max_depth, force_leaf)) {
            kind = KD_DEST_LEAF;
            at = leaf_base + base.s2;
            rec_info[child] = (int4)(KD_LEAF, at, count, depth + 1);
            base.s2 += count;
        } else {
            kind = KD_DEST_LARGE;
            at = base.s0;
            next_lo[base.s3] = lo;
            next_hi[base.s3] = hi;
            next_info[base.s3] = (int4)(at, count, child, (depth + 1) | (bad << 16));
            base.s0 += count;
            base.s3 += 1;
        }
        dest[2 * side] = kind;
        dest[2 * side + 1] = at;
    }
    node_dest[i] = (int4)(dest[0], dest[1], dest[2], dest[3]);
}

__kernel void KdBuild_large_emit(
    const __global float4 *act_lo, const __global float4 *act_hi,
    const __global int4 *act_info, const __global float *node_split,
    const __global int *node_mode, const __global int *node_chain,
    const __global int2 *chain_cut, const __global int2 *node_counts,
    const __global int8 *counter_scan, const int n, const int max_depth,
    const int force_leaf, const int rec_base, const int root_base,
    const int small_el_base, const int leaf_base, __global float4 *rec_lo,
    __global float4 *rec_hi, __global int4 *rec_info, __global float *rec_split,
    __global float4 *next_lo, __global float4 *next_hi,
    __global int4 *next_info, __global int4 *small_roots,
    __global int4 *node_dest) {
    int i = Launch_global_id();
    if (i < n)
        KdBuild_large_emit_at(i, act_lo, act_hi, act_info, node_split, node_mode, node_chain, chain_cut, node_counts,
                              counter_scan, max_depth, force_leaf, rec_base, root_base, small_el_base, leaf_base, rec_lo,
                              rec_hi, rec_info, rec_split, next_lo, next_hi, next_info, small_roots, node_dest);
}

/* Element e of node `node` (its flag, its rank among the node's elements
 * on each side: the flags' prefix at e less that at the node's first
 * element) copied to each side it goes to: into the next level's
 * elements, the small roots' elements, or a leaf's triangle list. */
inline void KdBuild_large_scatter_at(
    int e, int node, long flag, long rank, const __global int *el_tri, const __global float4 *below_lo,
    const __global float4 *below_hi, const __global float4 *above_lo, const __global float4 *above_hi,
    const __global int4 *node_dest, __global int *next_tri, __global float4 *next_lo, __global float4 *next_hi,
    __global int *small_tri, __global float4 *small_lo, __global float4 *small_hi, __global int *leaf_tris) {
    int4 dest = node_dest[node];
    int tri = el_tri[e];
    for (int side = 0; side < 2; ++side) {
        if (((flag >> (32 * side)) & 1) == 0) continue;
        int kind = side == 0 ? dest.x : dest.z;
        int at = (side == 0 ? dest.y : dest.w) + (int)((rank >> (32 * side)) & 0xffffffffL);
        float4 lo = side == 0 ? below_lo[e] : above_lo[e];
        float4 hi = side == 0 ? below_hi[e] : above_hi[e];
        if (kind == KD_DEST_LARGE) {
            next_tri[at] = tri;
            next_lo[at] = lo;
            next_hi[at] = hi;
        } else if (kind == KD_DEST_SMALL) {
            small_tri[at] = tri;
            small_lo[at] = lo;
            small_hi[at] = hi;
        } else if (kind == KD_DEST_LEAF) {
            leaf_tris[at] = tri;
        }
    }
}

/* KdBuild_large_scatter_at for elements first .. end - 1 of n (a run, or
 * all of them): the flags' prefix summed along them, a node's prefix taken
 * where its first element is met (a node begun before `first` looks it
 * up). A node's elements lie in a row from its first. */
inline void KdBuild_large_scatter_run(
    int first, int end, int n, const __global int *el_tri, const __global int *el_node,
    const __global int4 *act_info, const __global long *flags, const __global long *run_scan,
    const __global long *flag_total, const __global float4 *below_lo, const __global float4 *below_hi,
    const __global float4 *above_lo, const __global float4 *above_hi, const __global int4 *node_dest,
    __global int *next_tri, __global float4 *next_lo, __global float4 *next_hi, __global int *small_tri,
    __global float4 *small_lo, __global float4 *small_hi, __global int *leaf_tris) {
    long prefix = KdBuild_flag_prefix(first, n, flags, run_scan, flag_total), base = 0;
    int node = -1;
    for (int e = first; e < end; ++e) {
        if (el_node[e] != node) {
            node = el_node[e];
            int node_first = act_info[node].x;
            base = node_first == e ? prefix : KdBuild_flag_prefix(node_first, n, flags, run_scan, flag_total);
        }
        long flag = flags[e];
        KdBuild_large_scatter_at(e, node, flag, prefix - base, el_tri, below_lo, below_hi, above_lo, above_hi,
                                 node_dest, next_tri, next_lo, next_hi, small_tri, small_lo, small_hi, leaf_tris);
        prefix += flag;
    }
}

__kernel void KdBuild_large_scatter(
    const __global int *el_tri, const __global int *el_node,
    const __global int4 *act_info, const __global long *flags,
    const __global long *run_scan, const __global long *flag_total,
    const __global float4 *below_lo,
    const __global float4 *below_hi, const __global float4 *above_lo,
    const __global float4 *above_hi, const __global int4 *node_dest,
    const int n, __global int *next_tri, __global float4 *next_lo,
    __global float4 *next_hi, __global int *small_tri,
    __global float4 *small_lo, __global float4 *small_hi,
    __global int *leaf_tris) {
    int first = Launch_global_id() * KD_RUN, end = min(n, first + KD_RUN);
    if (first < n)
        KdBuild_large_scatter_run(first, end, n, el_tri, el_node, act_info, flags, run_scan, flag_total, below_lo,
                                  below_hi, above_lo, above_hi, node_dest, next_tri, next_lo, next_hi, small_tri,
                                  small_lo, small_hi, leaf_tris);
}

/* ---- small-node stage --------------------------------------------------- */

/* Per small root: tags its elements with it and makes it the first small
 * node, holding all its elements. */
inline void KdBuild_small_init_at(int r, const __global int4 *small_roots, __global int *sel_root,
                                  __global int2 *sn_node, __global ulong *sn_mask) {
    int4 root = small_roots[r];
    for (int k = 0; k < root.y; ++k) sel_root[root.x + k] = r;
    sn_node[r] = (int2)(r, root.z);
    sn_mask[r] = root.y == 64 ? ~0UL : ((1UL << root.y) - 1UL);
}

__kernel void KdBuild_small_init(const __global int4 *small_roots, const int n,
                                 __global int *sel_root, __global int2 *sn_node,
                                 __global ulong *sn_mask) {
    int r = Launch_global_id();
    if (r < n) KdBuild_small_init_at(r, small_roots, sel_root, sn_node, sn_mask);
}

/* Per candidate plane (6 per small-root element: its bounds' low and high
 * face on each axis): masks of the root's elements below and above it.
 * Candidate 6 e + 2 axis + side comes from element e's low (side 0, low
 * rule) or high (side 1, high rule) face, so its own element lands on the
 * side it bounds. */
inline void KdBuild_small_masks_at(int c, const __global int4 *small_roots, const __global int *sel_root,
                                   const __global float4 *sel_lo, const __global float4 *sel_hi,
                                   __global ulong2 *cand) {
    int e = c / 6, axis = (c % 6) >> 1, side = c & 1;
    int4 root = small_roots[sel_root[e]];
    float plane = Axis_of(side ? sel_hi[e] : sel_lo[e], axis);
    /* the root's bounds on this axis, read as floats (every fourth one) */
    const __global float *lo = (const __global float *)(sel_lo + root.x) + axis;
    const __global float *hi = (const __global float *)(sel_hi + root.x) + axis;
    ulong below = 0, above = 0;
    for (int k = 0; k < root.y; ++k) {
        int s = KdBuild_sides(lo[4 * k], hi[4 * k], plane, side == 0);
        below |= (ulong)(s & 1) << k;
        above |= (ulong)(s >> 1) << k;
    }
    cand[c] = (ulong2)(below, above);
}

__kernel void KdBuild_small_masks(const __global int4 *small_roots,
                                  const __global int *sel_root,
                                  const __global float4 *sel_lo,
                                  const __global float4 *sel_hi, const int n,
                                  __global ulong2 *cand) {
    int c = Launch_global_id();
    if (c < n) KdBuild_small_masks_at(c, small_roots, sel_root, sel_lo, sel_hi, cand);
}

/* The masks of candidate e on one axis and side (plane p): below the
 * elements of mask b, above those of mask a, and an element flat in the
 * plane (lo >= p >= hi, only ever one of the `flat` ones) on the side
 * KdBuild_sides gives it: above under the low rule (side 0), below under
 * the high rule. */
inline void KdBuild_store_masks(int e, int axis, int side, float p, ulong b, ulong a, ulong flat,
                                const __global float *lo, const __global float *hi, int4 root, __global ulong2 *cand) {
    ulong in_plane = 0UL;
    for (ulong left = flat; left != 0UL; left &= left - 1UL) {
        int k = popcount((left & (~left + 1UL)) - 1UL);
        in_plane |= (ulong)(lo[4 * k] >= p && hi[4 * k] <= p) << k;
    }
    cand[6 * (root.x + e) + 2 * axis + side] = side ? (ulong2)(b | in_plane, a) : (ulong2)(b, a | in_plane);
}

/* KdBuild_small_masks_at for the 2 n candidates of small root r on one
 * axis at once (a CPU's form: a root's O(n^2) comparisons become two
 * sorts and two sweeps). By KdBuild_sides, an element is below a plane p
 * where lo < p (the low rule) and above it where hi > p, which are
 * prefixes of the elements sorted by lo and suffixes of those sorted by
 * hi; elements flat in the plane are placed by KdBuild_store_masks. The
 * planes at the low faces are met in the order of the lo sort, those at
 * the high faces in the order of the hi sort, so each count (values below
 * p, or at most p) is a pointer that only moves forward. The hi sort
 * starts from the lo sort's order, which a mesh's small triangles nearly
 * keep. The same masks bit for bit as the per-candidate form. */
inline void KdBuild_small_masks_sorted_at(int r, int axis, const __global int4 *small_roots,
                                          const __global float4 *sel_lo, const __global float4 *sel_hi,
                                          __global ulong2 *cand) {
    int4 root = small_roots[r];
    int n = root.y;
    const __global float *lo = (const __global float *)(sel_lo + root.x) + axis;
    const __global float *hi = (const __global float *)(sel_hi + root.x) + axis;
    float lo_sorted[KD_SMALL], hi_sorted[KD_SMALL];
    int lo_order[KD_SMALL], hi_order[KD_SMALL];
    SortSmall_coordinate(lo, n, lo_sorted, lo_order);
    SortSmall_coordinate_in(hi, n, lo_order, hi_sorted, hi_order);
    /* below[j]: the j lowest by lo; above[j]: all but the j lowest by hi */
    ulong below[KD_SMALL + 1], above[KD_SMALL + 1];
    below[0] = 0UL;
    above[n] = 0UL;
    for (int j = 0; j < n; ++j) {
        below[j + 1] = below[j] | (1UL << lo_order[j]);
        above[n - 1 - j] = above[n - j] | (1UL << hi_order[n - 1 - j]);
    }
    ulong flat = 0UL;
    for (int k = 0; k < n; ++k) flat |= (ulong)(lo[4 * k] >= hi[4 * k]) << k;
    /* low faces: lo values below p start the run of p's ties; hi values at most p */
    int run = 0, h = 0;
    for (int j = 0; j < n; ++j) {
        float p = lo_sorted[j];
        if (j == 0 || lo_sorted[j - 1] < p) run = j;
        while (h < n && hi_sorted[h] <= p) h++;
        KdBuild_store_masks(lo_order[j], axis, 0, p, below[run], above[h], flat, lo, hi, root, cand);
    }
    /* high faces: lo values below p; hi values at most p end the run of p's ties */
    int l = 0;
    h = 0;
    for (int j = 0; j < n; ++j) {
        float p = hi_sorted[j];
        while (l < n && lo_sorted[l] < p) l++;
        while (h < n && hi_sorted[h] <= p) h++;
        KdBuild_store_masks(hi_order[j], axis, 1, p, below[l], above[h], flat, lo, hi, root, cand);
    }
}

/* One work-item per small root and axis (root r = i / 3). */
__kernel void KdBuild_small_masks_sorted(const __global int4 *small_roots, const __global float4 *sel_lo,
                                         const __global float4 *sel_hi, const int n, __global ulong2 *cand) {
    int i = Launch_global_id();
    if (i < n) KdBuild_small_masks_sorted_at(i / 3, i % 3, small_roots, sel_lo, sel_hi, cand);
}

/* The plane of candidate c (6 per element: low and high face on each axis)
 * of element e, read as one float of its bounds. */
inline float KdBuild_plane(const __global float4 *sel_lo, const __global float4 *sel_hi, int e, int c) {
    const __global float *face = (const __global float *)((c & 1) ? sel_hi : sel_lo);
    return face[4 * e + ((c % 6) >> 1)];
}

/* A small node's cell as its SAH search reads it: bounds, and per axis the
 * two terms of a child's half surface area with the split on that axis,
 * cap (the face across the axis) + length along it x side (its
 * perimeter's half): A_below / 2 = cap + (plane - lo) side. */
typedef struct {
    float4 lo, hi, cap, side;
} KdSahCell;

inline KdSahCell KdBuild_sah_cell(float4 lo, float4 hi) {
    float4 d = hi - lo;
    KdSahCell cell = {lo, hi, (float4)(d.y * d.z, d.z * d.x, d.x * d.y, 0.0f),
                      (float4)(d.y + d.z, d.z + d.x, d.x + d.y, 0.0f)};
    return cell;
}

/* SAH cost of candidate c, the plane at `plane` on `axis` with element
 * masks m (below, above), for a node with element mask `mask`, up to the
 * node's constants: N_below A_below / 2 + N_above A_above / 2 (the cost is
 * C_t + that x 2 / A); kept in *best_raw / *best_cand when lower. Planes
 * outside the open cell are skipped. */
inline void KdBuild_consider_plane(int c, int axis, float plane, ulong2 m, ulong mask, const KdSahCell *cell,
                                   float *best_raw, int *best_cand) {
    float lo = Axis_of(cell->lo, axis), hi = Axis_of(cell->hi, axis);
    if (!(lo < plane && plane < hi)) return;
    /* counts through int: a ulong's conversion to float is a slow sequence
     * on a CPU (Intel's runtime: the kernel 30 ms against 45) */
    float below = (float)(int)popcount(m.x & mask);
    float above = (float)(int)popcount(m.y & mask);
    float cap = Axis_of(cell->cap, axis), side = Axis_of(cell->side, axis);
    float raw = below * (cap + (plane - lo) * side) + above * (cap + (hi - plane) * side);
    if (raw < *best_raw) {
        *best_raw = raw;
        *best_cand = c;
    }
}

/* KdBuild_consider_plane for candidate c of the small root's element k. */
inline void KdBuild_consider(int c, int k, ulong mask, int4 root, const KdSahCell *cell,
                             const __global float4 *sel_lo, const __global float4 *sel_hi,
                             const __global ulong2 *cand, float *best_raw, int *best_cand) {
    KdBuild_consider_plane(c, (c % 6) >> 1, KdBuild_plane(sel_lo, sel_hi, root.x + k, c), cand[6 * root.x + c], mask,
                           cell, best_raw, best_cand);
}

/* Raw costs (KdBuild_consider_plane's expression) of three planes, on x, y
 * and z, as the lanes x, y, z; infinity where a plane is outside the open
 * cell. */
inline float4 KdBuild_raw3(float4 plane, float4 below, float4 above, const KdSahCell *cell) {
    float4 raw = below * (cell->cap + (plane - cell->lo) * cell->side) +
                 above * (cell->cap + (cell->hi - plane) * cell->side);
    return select((float4)(INFINITY), raw, isless(cell->lo, plane) & isless(plane, cell->hi));
}

/* Candidate c with raw cost raw kept when it is the cheapest so far. */
inline void KdBuild_keep(float raw, int c, float *best_raw, int *best_cand) {
    if (raw < *best_raw) {
        *best_raw = raw;
        *best_cand = c;
    }
}

/* The six candidates of the small root's element k: its low faces' costs
 * and its high faces' each as one float4 (the same floats as one plane at
 * a time), kept in candidate order (low, high face on x, then y, then z). */
inline void KdBuild_consider_element(int k, ulong mask, int4 root, const KdSahCell *cell,
                                     const __global float4 *sel_lo, const __global float4 *sel_hi,
                                     const __global ulong2 *cand, float *best_raw, int *best_cand) {
    const __global ulong2 *m = cand + 6 * (root.x + k);
    ulong2 m0 = m[0], m1 = m[1], m2 = m[2], m3 = m[3], m4 = m[4], m5 = m[5];
    /* counts through int, as KdBuild_consider_plane's */
    float4 below_lo = (float4)((float)(int)popcount(m0.x & mask), (float)(int)popcount(m2.x & mask),
                               (float)(int)popcount(m4.x & mask), 0.0f);
    float4 above_lo = (float4)((float)(int)popcount(m0.y & mask), (float)(int)popcount(m2.y & mask),
                               (float)(int)popcount(m4.y & mask), 0.0f);
    float4 below_hi = (float4)((float)(int)popcount(m1.x & mask), (float)(int)popcount(m3.x & mask),
                               (float)(int)popcount(m5.x & mask), 0.0f);
    float4 above_hi = (float4)((float)(int)popcount(m1.y & mask), (float)(int)popcount(m3.y & mask),
                               (float)(int)popcount(m5.y & mask), 0.0f);
    float4 raw_lo = KdBuild_raw3(sel_lo[root.x + k], below_lo, above_lo, cell);
    float4 raw_hi = KdBuild_raw3(sel_hi[root.x + k], below_hi, above_hi, cell);
    int c = 6 * k;
    KdBuild_keep(raw_lo.x, c, best_raw, best_cand);
    KdBuild_keep(raw_hi.x, c + 1, best_raw, best_cand);
    KdBuild_keep(raw_lo.y, c + 2, best_raw, best_cand);
    KdBuild_keep(raw_hi.y, c + 3, best_raw, best_cand);
    KdBuild_keep(raw_lo.z, c + 4, best_raw, best_cand);
    KdBuild_keep(raw_hi.z, c + 5, best_raw, best_cand);
}

/* The share of lane `lane` (of KD_SAH_LANES) in small node i's search: its
 * cheapest candidate and raw cost (-1 and infinity where none is searched,
 * see KdBuild_consider_plane), the factor 2 / A that makes the raw cost
 * over C_t the SAH cost, and the node's leaf cost. */
inline void KdBuild_search(int i, int lane, const __global int2 *sn_node, const __global ulong *sn_mask,
                           const __global int4 *small_roots, const __global float4 *rec_lo,
                           const __global float4 *rec_hi, const __global int4 *rec_info,
                           const __global float4 *sel_lo, const __global float4 *sel_hi,
                           const __global ulong2 *cand, int max_depth, float *my_raw, int *my_cand,
                           float *scale, float *leaf_cost) {
    int2 node = sn_node[i];
    ulong mask = sn_mask[i];
    int4 root = small_roots[node.x];
    float4 lo = rec_lo[node.y], hi = rec_hi[node.y];
    float area = KdBuild_area(lo, hi);
    *scale = 2.0f / area;
    *leaf_cost = (float)(int)popcount(mask);
    if (rec_info[node.y].w < max_depth && area > 0.0f && *leaf_cost > KD_COST_TRAVERSE) {
        KdSahCell cell = KdBuild_sah_cell(lo, hi);
#if KD_SAH_LANES == 1
        /* the candidates of the node's elements only, lowest bit first */
        for (ulong left = mask; left != 0UL; left &= left - 1UL)
            KdBuild_consider_element(popcount((left & (~left + 1UL)) - 1UL), mask, root, &cell, sel_lo, sel_hi, cand,
                                     my_raw, my_cand);
#else
        for (int c = lane; c < 6 * root.y; c += KD_SAH_LANES) {
            int k = c / 6;
            if (((mask >> k) & 1UL) != 0UL) KdBuild_consider(c, k, mask, root, &cell, sel_lo, sel_hi, cand, my_raw, my_cand);
        }
#endif
    }
}

/* Whether a node with its cheapest candidate's raw cost splits rather
 * than stays a leaf: C_t + raw x 2 / A below the leaf cost. */
inline bool KdBuild_splits(float raw, float scale, float leaf_cost) {
    return KD_COST_TRAVERSE + raw * scale < leaf_cost;
}

/* Per small node (KD_SAH_LANES work-items each, sharing its candidates):
 * the candidate inside the node's cell with the lowest SAH
 *   C_t + (N_below A_below + N_above A_above) / A,
 * counts by popcount of the candidate's masks and the node's mask. best is
 * the candidate, or -1 where a leaf (cost: its triangle count) is cheaper
 * or the depth limit is reached; a node of at most C_t triangles is a leaf
 * at once, as no split costs less than C_t. The lanes compare raw costs
 * (KdBuild_consider_plane) and ties go to the lowest candidate, so the
 * choice does not depend on the lane count. The global
 * size is a multiple of the work-group size, itself a multiple of
 * KD_SAH_LANES. */
__kernel void KdBuild_small_best(const __global int2 *sn_node,
                                 const __global ulong *sn_mask,
                                 const __global int4 *small_roots,
                                 const __global float4 *rec_lo,
                                 const __global float4 *rec_hi,
                                 const __global int4 *rec_info,
                                 const __global float4 *sel_lo,
                                 const __global float4 *sel_hi,
                                 const __global ulong2 *cand, const int n,
                                 const int max_depth, __global int *best) {
    __local float raw_s[KD_SAH_GROUP];
    __local int cand_s[KD_SAH_GROUP];
    int i = Launch_global_id() / KD_SAH_LANES, lane = Launch_global_id() % KD_SAH_LANES;
    int lid = get_local_id(0);
    float my_raw = INFINITY, scale = 0.0f, leaf_cost = 0.0f;
    int my_cand = -1;
    if (i < n)
        KdBuild_search(i, lane, sn_node, sn_mask, small_roots, rec_lo, rec_hi, rec_info, sel_lo, sel_hi, cand,
                       max_depth, &my_raw, &my_cand, &scale, &leaf_cost);
#if KD_SAH_LANES > 1
    /* the node's lanes agree on the cheapest, lowest candidate */
    raw_s[lid] = my_raw;
    cand_s[lid] = my_cand;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int s = KD_SAH_LANES / 2; s > 0; s >>= 1) {
        if (lane < s) {
            float other = raw_s[lid + s];
            int other_cand = cand_s[lid + s];
            if (other < raw_s[lid] || (other == raw_s[lid] && other_cand >= 0 &&
                                        (cand_s[lid] < 0 || other_cand < cand_s[lid]))) {
                raw_s[lid] = other;
                cand_s[lid] = other_cand;
            }
        }
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    my_raw = raw_s[lid];
    my_cand = cand_s[lid];
#endif
    if (i < n && lane == 0) best[i] = KdBuild_splits(my_raw, scale, leaf_cost) ? my_cand : -1;
}

/* Per small node: a split writes its record and two child small nodes
 * (masks: its mask and the candidate's); a leaf writes its record and its
 * triangles. rank packs (splits before it) | (leaf triangles before it)
 * << 32. */
inline void KdBuild_small_emit_at(
    int i, const __global int2 *sn_node, const __global ulong *sn_mask, const __global int *best,
    const __global long *rank, const __global int4 *small_roots, const __global int *sel_tri,
    const __global float4 *sel_lo, const __global float4 *sel_hi, const __global ulong2 *cand, int rec_base,
    int leaf_base, __global float4 *rec_lo, __global float4 *rec_hi, __global int4 *rec_info, __global float *rec_split,
    __global int2 *next_node, __global ulong *next_mask, __global int *leaf_tris) {
    int2 node = sn_node[i];
    ulong mask = sn_mask[i];
    int4 root = small_roots[node.x];
    int depth = rec_info[node.y].w;
    long r = rank[i];
    int c = best[i];
    if (c < 0) {
        int at = leaf_base + (int)(r >> 32);
        rec_info[node.y] = (int4)(KD_LEAF, at, popcount(mask), depth);
        for (ulong left = mask; left != 0UL; left &= left - 1UL)
            leaf_tris[at++] = sel_tri[root.x + popcount((left & (~left + 1UL)) - 1UL)];
        return;
    }
    int split = (int)(r & 0xffffffffL);
    int k = c / 6, axis = (c % 6) >> 1;
    float plane = KdBuild_plane(sel_lo, sel_hi, root.x + k, c);
    ulong2 m = cand[6 * root.x + c];
    int left = rec_base + 2 * split;
    float4 lo = rec_lo[node.y], hi = rec_hi[node.y];
    rec_info[node.y] = (int4)(axis, left, left + 1, depth);
    rec_split[node.y] = plane;
    rec_lo[left] = lo;
    rec_hi[left] = Axis_with(hi, axis, plane);
    rec_lo[left + 1] = Axis_with(lo, axis, plane);
    rec_hi[left + 1] = hi;
    rec_info[left] = rec_info[left + 1] = (int4)(KD_LEAF, 0, 0, depth + 1);
    next_node[2 * split] = (int2)(node.x, left);
    next_node[2 * split + 1] = (int2)(node.x, left + 1);
    next_mask[2 * split] = mask & m.x;
    next_mask[2 * split + 1] = mask & m.y;
}

__kernel void KdBuild_small_emit(
    const __global int2 *sn_node, const __global ulong *sn_mask,
    const __global int *best, const __global long *rank,
    const __global int4 *small_roots, const __global int *sel_tri,
    const __global float4 *sel_lo, const __global float4 *sel_hi,
    const __global ulong2 *cand, const int n, const int rec_base,
    const int leaf_base, __global float4 *rec_lo, __global float4 *rec_hi,
    __global int4 *rec_info, __global float *rec_split,
    __global int2 *next_node, __global ulong *next_mask,
    __global int *leaf_tris) {
    int i = Launch_global_id();
    if (i < n)
        KdBuild_small_emit_at(i, sn_node, sn_mask, best, rank, small_roots, sel_tri, sel_lo, sel_hi, cand, rec_base,
                              leaf_base, rec_lo, rec_hi, rec_info, rec_split, next_node, next_mask, leaf_tris);
}

/* ---- output stage ------------------------------------------------------- */

/* Whether record r is in the batch [begin, end). */
inline bool KdBuild_in(int r, int begin, int end) { return r >= begin && r < end; }

/* Whether inner record r's children were made in the batch [begin, end):
 * a node's chain of cuts (KdBuild_large_split_at) makes a level's records
 * one below another; any other record's children come in a later batch. */
inline bool KdBuild_chained(int4 info, int begin, int end) {
    return info.x != KD_LEAF && KdBuild_in(info.y, begin, end);
}

/* Subtree size of record p of the batch [begin, end), whose children made
 * in later batches are already sized: down a chain of cuts inside the
 * batch (one child of each cut its empty leaf, the other the kept part)
 * record by record. */
inline void KdBuild_subtree_size_at(int p, const __global int4 *rec_info, __global int *size, int begin, int end) {
    int total = 0;
    for (int q = p; q >= 0;) {
        int4 info = rec_info[q];
        total += 1;
        if (info.x == KD_LEAF) break;
        int next = -1;
        for (int side = 0; side < 2; ++side) {
            int c = side == 0 ? info.y : info.z;
            int4 child = rec_info[c];
            if (!KdBuild_in(c, begin, end)) total += size[c];
            else if (KdBuild_chained(child, begin, end)) next = c;
            else total += child.x == KD_LEAF ? 1 : 1 + size[child.y] + size[child.z];
        }
        q = next;
    }
    size[p] = total;
}

__kernel void KdBuild_subtree_size(const __global int4 *rec_info,
                                   const int begin, const int end,
                                   __global int *size) {
    int p = begin + Launch_global_id();
    if (p < end) KdBuild_subtree_size_at(p, rec_info, size, begin, end);
}

/* Preorder addresses of the children of record p of a batch, whose own
 * address is known: the left child follows its parent, the right child
 * follows the left subtree; and down a chain of cuts made in the next
 * batch [next_begin, next_end), the addresses of every record in it (its
 * records there, whose parents are in that batch too, are skipped when
 * that batch comes). */
inline void KdBuild_preorder_at(int p, const __global int4 *rec_info, const __global int *size,
                                __global int *addr, int begin, int end, int next_begin, int next_end) {
    int4 info = rec_info[p];
    if (info.x == KD_LEAF || KdBuild_chained(info, begin, end)) return;
    for (int q = p; q >= 0;) {
        addr[info.y] = addr[q] + 1;
        addr[info.z] = addr[q] + 1 + size[info.y];
        int next = -1;
        for (int side = 0; side < 2; ++side) {
            int c = side == 0 ? info.y : info.z;
            if (KdBuild_in(c, next_begin, next_end) && KdBuild_chained(rec_info[c], next_begin, next_end)) next = c;
        }
        q = next;
        if (q >= 0) info = rec_info[q];
    }
}

__kernel void KdBuild_preorder(const __global int4 *rec_info,
                               const __global int *size, const int begin,
                               const int end, const int next_begin,
                               const int next_end, __global int *addr) {
    int p = begin + Launch_global_id();
    if (p < end) KdBuild_preorder_at(p, rec_info, size, addr, begin, end, next_begin, next_end);
}

/* Every record to its preorder KdNode. */
inline void KdBuild_output_at(int p, const __global int4 *rec_info, const __global float *rec_split,
                              const __global int *addr, __global KdNode *nodes) {
    int4 info = rec_info[p];
    KdNode node;
    if (info.x == KD_LEAF) {
        node.split = 0.0f;
        node.axis = KD_LEAF;
        node.child = info.y;
        node.count = info.z;
    } else {
        node.split = rec_split[p];
        node.axis = info.x;
        node.child = addr[info.z];
        node.count = 0;
    }
    nodes[addr[p]] = node;
}

__kernel void KdBuild_output(const __global int4 *rec_info,
                             const __global float *rec_split,
                             const __global int *addr, const int n,
                             __global KdNode *nodes) {
    int p = Launch_global_id();
    if (p < n) KdBuild_output_at(p, rec_info, rec_split, addr, nodes);
}

/* ---- inputs of the host's scans and statistics ---------------------------- */

/* Chunks of each active large node. */
__kernel void KdBuild_chunk_counts(const __global int4 *act_info, const int n, __global int *counts) {
    int i = Launch_global_id();
    if (i < n) counts[i] = (act_info[i].y + KD_CHUNK - 1) / KD_CHUNK;
}

/* Per small node, what the rank scan adds up: 1 for a split (its two
 * children), or its triangle count in the high word for a leaf. */
__kernel void KdBuild_small_ranks(const __global int *best, const __global ulong *mask, const int n,
                                  __global long *ranks) {
    int i = Launch_global_id();
    if (i < n) ranks[i] = best[i] >= 0 ? 1L : ((long)popcount(mask[i]) << 32);
}

/* Per record: its SAH term (cost times surface area, x) and, for the
 * leaf statistics, (is a leaf, its size, its size, its depth). */
__kernel void KdBuild_statistics(const __global int4 *rec_info, const __global float4 *rec_lo,
                                 const __global float4 *rec_hi, const int n, __global float4 *terms,
                                 __global int4 *sizes) {
    int i = Launch_global_id();
    if (i >= n) return;
    int4 info = rec_info[i];
    bool leaf = info.x == KD_LEAF;
    terms[i] = (float4)((leaf ? (float)info.z : KD_COST_TRAVERSE) * KdBuild_area(rec_lo[i], rec_hi[i]), 0.0f, 0.0f, 0.0f);
    sizes[i] = leaf ? (int4)(1, info.z, info.z, info.w) : (int4)(0, 0, 0, info.w);
}

/* ---- the whole build in one work-item ------------------------------------ */

#if KD_SAH_LANES == 1
/* The build of kdtree_build.py (_Build) after its setup, by one work-item:
 * its level loops, scans and counters run here in order, calling the steps
 * the launched build runs per node, chunk, element and record, so that the
 * records, the leaf lists and the tree are the same bit for bit (its SAH
 * searches take one lane, so it exists where KD_SAH_LANES is 1). For small
 * meshes on a CPU device, where each launch of the level-by-level build
 * costs far more than its work. `caps` are the capacities (elements, active
 * nodes, chunks, small elements and roots, records, leaf references, small
 * nodes, batches) of the arrays passed; a build that would outgrow one stops
 * with result[0] = 1 (the host then builds level by level). Else result:
 * 0, records, leaf references, small roots, small elements, large and small
 * levels; `nodes` holds the tree. The root record and the root as the one
 * active node (act_*[0]) are written by the host; el_* hold the elements. */
__kernel void KdBuild_serial(
    const __global float4 *verts, const int count, const int max_depth, const float eps, const int budget,
    const int8 caps, __global float4 *rec_lo, __global float4 *rec_hi, __global int4 *rec_info,
    __global float *rec_split, __global int *el_tri, __global float4 *el_lo, __global float4 *el_hi,
    __global int *nel_tri, __global float4 *nel_lo, __global float4 *nel_hi, __global int *el_node,
    __global long *flags, __global long *run_scan, __global long *flag_total, __global float4 *below_lo,
    __global float4 *below_hi, __global float4 *above_lo, __global float4 *above_hi, __global float4 *act_lo,
    __global float4 *act_hi, __global int4 *act_info, __global float4 *nact_lo, __global float4 *nact_hi,
    __global int4 *nact_info, __global int *chunk_base, __global float *node_split, __global int *node_mode,
    __global int *node_chain, __global int2 *chain_cut, __global int2 *node_counts, __global int8 *counters,
    __global int8 *counter_scan, __global int4 *node_dest,
    __global int *chunk_node, __global float4 *chunk_lo, __global float4 *chunk_hi, __global int4 *small_roots,
    __global int *sel_tri, __global float4 *sel_lo, __global float4 *sel_hi, __global int *sel_root,
    __global ulong2 *cand, __global int2 *sn_node, __global ulong *sn_mask, __global int2 *nsn_node,
    __global ulong *nsn_mask, __global int *best, __global long *rank, __global int *leaf_tris,
    __global int2 *batches, __global int *size, __global int *addr, __global KdNode *nodes, __global int *result) {
    if (Launch_global_id() != 0) return;
    int rec_count = 1, leaf_count = 0, root_count = 0, small_count = 0, n_batches = 1;
    int large_levels = 0, small_levels = 0;
    batches[0] = (int2)(0, 1);
    result[0] = 1;
    /* large-node stage (_Build.large_stage): a small root stays as it is */
    int active = 0, elements = count;
    if (count <= KD_SMALL) {
        for (int e = 0; e < count; ++e) {
            sel_tri[e] = el_tri[e];
            sel_lo[e] = el_lo[e];
            sel_hi[e] = el_hi[e];
        }
        small_roots[0] = (int4)(0, count, 0, 0);
        root_count = 1;
        small_count = count;
    } else {
        active = 1;
    }
    while (active) {
        large_levels++;
        int chunks = 0;
        for (int i = 0; i < active; ++i) {
            chunk_base[i] = chunks;
            chunks += (act_info[i].y + KD_CHUNK - 1) / KD_CHUNK;
        }
        if (chunks > caps.s2) return;
        for (int i = 0; i < active; ++i) KdBuild_chunk_nodes_at(i, act_info, chunk_base, chunk_node);
        for (int c = 0; c < chunks; ++c) {
            float4 lo, hi;
            KdBuild_chunk_lane(c, 0, 1, act_info, chunk_base, chunk_node, el_lo, el_hi, el_node, &lo, &hi);
            chunk_lo[c] = lo;
            chunk_hi[c] = hi;
        }
        int chain = 2 * elements <= budget; /* no child of this level can spend the budget */
        for (int i = 0; i < active; ++i)
            KdBuild_large_split_at(i, act_lo, act_hi, act_info, chunk_base, chunk_lo, chunk_hi, max_depth, chain,
                                   node_split, node_mode, node_chain, chain_cut);
        for (int e = 0; e < elements; ++e)
            KdBuild_large_classify_at(e, verts, el_tri, el_lo, el_hi, el_node, node_split, node_mode, eps, flags,
                                      below_lo, below_hi, above_lo, above_hi);
        long sum = 0;
        for (int e = 0; e < elements; ++e) {
            if (e % KD_RUN == 0) run_scan[e / KD_RUN] = sum;
            sum += flags[e];
        }
        flag_total[0] = sum;
        /* children counts, with every node a leaf once the element budget is spent */
        int8 total;
        int force_leaf = 0;
        for (; force_leaf < 2; ++force_leaf) {
            for (int i = 0; i < active; ++i)
                KdBuild_large_children_at(i, act_lo, act_hi, act_info, node_split, node_mode, node_chain, chain_cut,
                                          flags, run_scan, flag_total, elements, max_depth, force_leaf, node_counts,
                                          counters);
            total = (int8)(0);
            for (int i = 0; i < active; ++i) {
                counter_scan[i] = total;
                total += counters[i];
            }
            if (total.s0 <= budget) break;
        }
        force_leaf = min(force_leaf, 1);
        if (total.s0 > caps.s0 || total.s3 > caps.s1 || small_count + total.s1 > caps.s3 ||
            root_count + total.s4 > caps.s3 || rec_count + total.s5 > caps.s4 || leaf_count + total.s2 > caps.s5 ||
            n_batches == caps.s7)
            return;
        for (int i = 0; i < active; ++i)
            KdBuild_large_emit_at(i, act_lo, act_hi, act_info, node_split, node_mode, node_chain, chain_cut,
                                  node_counts, counter_scan, max_depth, force_leaf, rec_count, root_count, small_count,
                                  leaf_count, rec_lo, rec_hi, rec_info, rec_split, nact_lo, nact_hi, nact_info,
                                  small_roots, node_dest);
        KdBuild_large_scatter_run(0, elements, elements, el_tri, el_node, act_info, flags, run_scan, flag_total,
                                  below_lo, below_hi, above_lo, above_hi, node_dest, nel_tri, nel_lo, nel_hi, sel_tri,
                                  sel_lo, sel_hi, leaf_tris);
        batches[n_batches++] = (int2)(rec_count, rec_count + total.s5);
        rec_count += total.s5;
        root_count += total.s4;
        small_count += total.s1;
        leaf_count += total.s2;
        /* the children are the next level's nodes and elements */
        __global float4 *f;
        __global int4 *g;
        __global int *t;
        f = act_lo, act_lo = nact_lo, nact_lo = f;
        f = act_hi, act_hi = nact_hi, nact_hi = f;
        g = act_info, act_info = nact_info, nact_info = g;
        t = el_tri, el_tri = nel_tri, nel_tri = t;
        f = el_lo, el_lo = nel_lo, nel_lo = f;
        f = el_hi, el_hi = nel_hi, nel_hi = f;
        active = total.s3;
        elements = total.s0;
    }
    /* small-node stage (_Build.small_stage) */
    int small_active = root_count;
    if (root_count > caps.s6) return;
    for (int r = 0; r < root_count; ++r) KdBuild_small_init_at(r, small_roots, sel_root, sn_node, sn_mask);
#if KD_SORTED_MASKS
    for (int i = 0; i < 3 * root_count; ++i) KdBuild_small_masks_sorted_at(i / 3, i % 3, small_roots, sel_lo, sel_hi, cand);
#else
    for (int c = 0; c < 6 * small_count; ++c) KdBuild_small_masks_at(c, small_roots, sel_root, sel_lo, sel_hi, cand);
#endif
    while (small_active) {
        small_levels++;
        for (int i = 0; i < small_active; ++i) {
            float raw = INFINITY, scale = 0.0f, leaf_cost = 0.0f;
            int c = -1;
            KdBuild_search(i, 0, sn_node, sn_mask, small_roots, rec_lo, rec_hi, rec_info, sel_lo, sel_hi, cand,
                           max_depth, &raw, &c, &scale, &leaf_cost);
            best[i] = KdBuild_splits(raw, scale, leaf_cost) ? c : -1;
        }
        long packed = 0;
        for (int i = 0; i < small_active; ++i) {
            rank[i] = packed;
            packed += best[i] >= 0 ? 1L : ((long)popcount(sn_mask[i]) << 32);
        }
        int splits = (int)(packed & 0xffffffffL), leaf_new = (int)(packed >> 32);
        if (rec_count + 2 * splits > caps.s4 || leaf_count + leaf_new > caps.s5 || 2 * splits > caps.s6 ||
            n_batches == caps.s7)
            return;
        for (int i = 0; i < small_active; ++i)
            KdBuild_small_emit_at(i, sn_node, sn_mask, best, rank, small_roots, sel_tri, sel_lo, sel_hi, cand,
                                  rec_count, leaf_count, rec_lo, rec_hi, rec_info, rec_split, nsn_node, nsn_mask,
                                  leaf_tris);
        batches[n_batches++] = (int2)(rec_count, rec_count + 2 * splits);
        rec_count += 2 * splits;
        leaf_count += leaf_new;
        __global int2 *m = sn_node;
        sn_node = nsn_node, nsn_node = m;
        __global ulong *k = sn_mask;
        sn_mask = nsn_mask, nsn_mask = k;
        small_active = 2 * splits;
    }
    /* output stage (_Build.output_stage) */
    for (int b = n_batches - 1; b >= 0; --b)
        for (int p = batches[b].x; p < batches[b].y; ++p)
            KdBuild_subtree_size_at(p, rec_info, size, batches[b].x, batches[b].y);
    addr[0] = 0;
    for (int b = 0; b < n_batches; ++b) {
        int2 next = b + 1 < n_batches ? batches[b + 1] : (int2)(rec_count, rec_count);
        for (int p = batches[b].x; p < batches[b].y; ++p)
            KdBuild_preorder_at(p, rec_info, size, addr, batches[b].x, batches[b].y, next.x, next.y);
    }
    for (int p = 0; p < rec_count; ++p) KdBuild_output_at(p, rec_info, rec_split, addr, nodes);
    result[0] = 0;
    result[1] = rec_count;
    result[2] = leaf_count;
    result[3] = root_count;
    result[4] = small_count;
    result[5] = large_levels;
    result[6] = small_levels;
}
#endif
