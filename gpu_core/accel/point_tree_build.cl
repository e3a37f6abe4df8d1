/* Point kd-tree construction on the device [ZHWG08], breadth-first: every
 * kernel here handles all nodes (or chunks of points) of one tree level at
 * once; the host only loops over levels and reads one word of list sizes
 * per level.
 *
 * Large-node stage: a node's points are a contiguous segment of the working
 * array, processed in chunks of POINT_BUILD_CHUNK. Each level cuts off
 * empty space and splits what keeps the points at the spatial median of
 * its cell's longest axis (or, with no side to cut, splits the node so),
 * then partitions the segments stably into the other of two point arrays,
 * which becomes the working one. The host does not read the number of
 * chunks: it launches the chunk kernels over a bound (n_active + n /
 * POINT_BUILD_CHUNK) and they find the count on the device; each level
 * lists the next one's nodes and chunks. Small-node
 * stage (<= POINT_BUILD_SMALL points): the small root's points are fixed;
 * a node is a bit mask over them, and the split is the candidate plane (a
 * point coordinate) of least VVH cost. Output stage: subtree
 * sizes and photon sums bottom-up, preorder addresses top-down, then the
 * traversal nodes, node payloads and points in leaf order. */
#include "device/launch.h"
#include "device/axis.h"
#include "device/sort_small.h"
#include "accel/point_tree.h"

/* axis value of a node whose points are all identical: split by count */
#define BUILD_COUNT_SPLIT 4

/* The plane that partitions an active large node's points this level: its
 * own split, or, after an empty-space cut, the split of X, the part that
 * keeps the points (x_plane: X's split, its axis, 1 when X is the right
 * child, as int bits; axis -1 when there is no X). */
typedef struct {
    int axis;
    float split;
} PointBuildPlane;

inline PointBuildPlane PointBuild_partition(const BuildNode *nd, float4 x_plane) {
    int x_axis = as_int(x_plane.y);
    return x_axis >= 0 ? (PointBuildPlane){x_axis, x_plane.x} : (PointBuildPlane){nd->axis, nd->split};
}

/* Side of a point of a large node of `count` points; rank = its position in
 * the node's segment. */
inline bool PointBuild_goes_left(PointBuildPlane plane, int count, float4 p, int rank) {
    if (plane.axis == BUILD_COUNT_SPLIT) return rank < count / 2;
    return Axis_of(p, plane.axis) < plane.split;
}

/* Points of active node j that go left, from the inclusive scans of the
 * chunks per node (chunk_end) and of the chunks' left counts (left_end). */
inline int PointBuild_left_count(const __global int *chunk_end, const __global int *left_end, int j) {
    int first = j > 0 ? chunk_end[j - 1] : 0;
    return left_end[chunk_end[j] - 1] - (first > 0 ? left_end[first - 1] : 0);
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
    return n_active > 0 ? chunk_end[n_active - 1] : 0;
}

/* The `n` chunks of the node of `count` points from `start`, the
 * active list's `slot`-th, at chunks[at...]. */
inline void PointBuild_write_chunks(__global Chunk *chunks, int at, int n, int slot, int start, int count) {
    for (int c = 0; c < n; ++c) {
        Chunk ch;
        ch.slot = slot;
        ch.start = start + c * POINT_BUILD_CHUNK;
        ch.count = min(POINT_BUILD_CHUNK, count - c * POINT_BUILD_CHUNK);
        ch.rank = c;
        chunks[at + c] = ch;
    }
}

/* The root's chunks (chunk_end[0]: their number, set by the host). */
__kernel void PointBuild_root_chunks(const __global BuildNode *nodes, const __global int *chunk_end,
                                     __global Chunk *chunks) {
    if (Launch_global_id() != 0) return;
    PointBuild_write_chunks(chunks, 0, chunk_end[0], 0, nodes[0].start, nodes[0].count);
}

/* Bounding box of chunk c's points. */
inline void PointBuild_chunk_bounds_at(int c, const __global Chunk *chunks, const __global float4 *pts,
                                       __global float4 *chunk_lo, __global float4 *chunk_hi) {
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

/* The launched large stage's kernels read the level's active node count
 * from the device (active_count[0]: the last level's count of large
 * nodes), and are launched over a bound of it, so that the host queues a
 * level before it has read how many nodes the level before made. */
__kernel void PointBuild_chunk_bounds(const __global Chunk *chunks, const __global float4 *pts,
                                 __global float4 *chunk_lo, __global float4 *chunk_hi,
                                 const __global int *chunk_end, const __global int *active_count) {
    int c = Launch_global_id();
    if (c < PointBuild_chunk_total(chunk_end, active_count[0]))
        PointBuild_chunk_bounds_at(c, chunks, pts, chunk_lo, chunk_hi);
}

/* Spatial-median split of the longest axis of the cell lo..hi that the
 * points (tight box tlo..thi) span; BUILD_COUNT_SPLIT when they all coincide. */
inline PointBuildPlane PointBuild_median(float4 lo, float4 hi, float4 tlo, float4 thi) {
    float4 ext = hi - lo, text = thi - tlo;
    int a = 0;
    float longest = -1.0f;
    for (int k = 0; k < 3; ++k) {
        if (Axis_of(text, k) > 0.0f && Axis_of(ext, k) > longest) {
            longest = Axis_of(ext, k);
            a = k;
        }
    }
    if (longest < 0.0f) return (PointBuildPlane){BUILD_COUNT_SPLIT, tlo.x};
    float t0 = Axis_of(tlo, a), t1 = Axis_of(thi, a);
    float split = 0.5f * (Axis_of(lo, a) + Axis_of(hi, a));
    if (!(split > t0 && split <= t1)) split = 0.5f * (t0 + t1);
    if (!(split > t0)) split = t1; /* t0 and t1 adjacent floats */
    return (PointBuildPlane){a, split};
}

/* Per active node: reduce its chunks to the tight box, then cut off empty
 * space (the side with the largest empty fraction of the cell, when over
 * empty_ratio) and split the part that keeps the points, X, at the spatial
 * median of its cell's longest axis (x_plane; X is split one level deeper,
 * in the same pass), or, with no side to cut, split the node itself there.
 * A cut leaves the points on one side and nothing on the other. */
inline void PointBuild_large_decide_at(int j, const __global int *active, __global BuildNode *nodes,
                                      const __global int *chunk_end, const __global float4 *chunk_lo,
                                      const __global float4 *chunk_hi, float empty_ratio, int max_depth,
                                      __global float4 *x_plane) {
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
    }
    float4 ext = nd.hi - nd.lo;

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
        /* low cut: every point is >= tlo goes right; high cut: every point is
         * < the next float above thi goes left */
        float plane = cut_low ? Axis_of(tlo, cut_axis) : nextafter(Axis_of(thi, cut_axis), INFINITY);
        nd.axis = cut_axis;
        nd.split = plane;
        nodes[id] = nd;
        float4 xlo = cut_low ? Axis_with(nd.lo, cut_axis, plane) : nd.lo;
        float4 xhi = cut_low ? nd.hi : Axis_with(nd.hi, cut_axis, plane);
        /* X at the depth limit stays unsplit (a leaf) */
        PointBuildPlane x = nd.depth + 1 < max_depth ? PointBuild_median(xlo, xhi, tlo, thi) : (PointBuildPlane){-1, 0.0f};
        x_plane[j] = (float4)(x.split, as_float(x.axis), as_float(cut_low ? 1 : 0), 0.0f);
        return;
    }
    PointBuildPlane m = PointBuild_median(nd.lo, nd.hi, tlo, thi);
    nd.axis = m.axis;
    nd.split = m.split;
    nodes[id] = nd;
    x_plane[j] = (float4)(0.0f, as_float(-1), 0.0f, 0.0f);
}

__kernel void PointBuild_large_decide(const __global int *active, __global BuildNode *nodes,
                                 const __global int *chunk_end, const __global float4 *chunk_lo,
                                 const __global float4 *chunk_hi, const float empty_ratio,
                                 const int max_depth, __global float4 *x_plane,
                                 const __global int *active_count) {
    int j = Launch_global_id();
    if (j < active_count[0])
        PointBuild_large_decide_at(j, active, nodes, chunk_end, chunk_lo, chunk_hi, empty_ratio, max_depth, x_plane);
}

/* Points of chunk c that go to the left child. */
inline int PointBuild_chunk_count_left_at(int c, const __global Chunk *chunks, const __global int *active,
                                          const __global BuildNode *nodes, const __global float4 *x_plane,
                                          const __global float4 *pts) {
    Chunk ch = chunks[c];
    BuildNode nd = nodes[active[ch.slot]];
    PointBuildPlane plane = PointBuild_partition(&nd, x_plane[ch.slot]);
    int n = 0;
    for (int i = 0; i < ch.count; ++i)
        n += PointBuild_goes_left(plane, nd.count, pts[ch.start + i], ch.rank * POINT_BUILD_CHUNK + i) ? 1 : 0;
    return n;
}

/* Each chunk's left count; 0 past the last chunk, up to the bound, so that
 * the bound's prefix sums hold. */
__kernel void PointBuild_chunk_count_left(const __global Chunk *chunks, const __global int *active,
                                     const __global BuildNode *nodes, const __global float4 *x_plane,
                                     const __global float4 *pts, __global int *chunk_left,
                                     const __global int *chunk_end, const __global int *active_count,
                                     const int bound) {
    int c = Launch_global_id();
    if (c >= bound) return;
    chunk_left[c] = c < PointBuild_chunk_total(chunk_end, active_count[0])
                        ? PointBuild_chunk_count_left_at(c, chunks, active, nodes, x_plane, pts)
                        : 0;
}

/* Class of a new node as counters, scanned together: s0 1 when it is
 * large (split again) and s2 its chunks, s1 1 when it is a small root;
 * all 0 for a leaf. */
inline int8 PointBuild_class(int count, int depth, int max_depth) {
    int8 c = (int8)(0);
    if (depth >= max_depth) return c;
    if (count > POINT_BUILD_SMALL) {
        c.s0 = 1;
        c.s2 = (count + POINT_BUILD_CHUNK - 1) / POINT_BUILD_CHUNK;
    } else if (count >= 2) {
        c.s1 = 1;
    }
    return c;
}

/* Two unused slots of the node table at `at` (a node without a cut-off X
 * leaves its X's children's slots empty): count -1, never referenced. */
inline void PointBuild_store_holes(__global BuildNode *nodes, int at) {
    BuildNode hole;
    hole.lo = hole.hi = (float4)(0.0f);
    hole.start = hole.root = hole.left = hole.axis = hole.depth = -1;
    hole.count = -1;
    hole.mask = 0u;
    hole.split = 0.0f;
    nodes[at] = hole;
    nodes[at + 1] = hole;
}

/* The cells of the two sides of `plane` within nd's cell. */
inline void PointBuild_sides(const BuildNode *nd, PointBuildPlane plane, BuildNode *l, BuildNode *r) {
    l->lo = r->lo = nd->lo;
    l->hi = r->hi = nd->hi;
    if (plane.axis != BUILD_COUNT_SPLIT) {
        l->hi = Axis_with(l->hi, plane.axis, plane.split);
        r->lo = Axis_with(r->lo, plane.axis, plane.split);
    }
    l->mask = r->mask = 0u;
    l->root = r->root = -1;
}

/* Create the children of every active node j at child_base + 2 j and, after
 * an empty-space cut, the children of X at child_base + 2 slots + 2 j
 * (holes otherwise), with their classes (PointBuild_class) in the
 * same slots of `classes`; left_end is the inclusive scan of the chunks'
 * left counts. `slots`: the active nodes the level has room for, at least
 * their number. */
inline void PointBuild_large_split_at(int j, const __global int *active, __global BuildNode *nodes,
                                     const __global int *chunk_end, const __global int *left_end,
                                     const __global float4 *x_plane, int child_base, int max_depth,
                                     __global int8 *classes, int slots) {
    int id = active[j];
    BuildNode nd = nodes[id];
    int n_left = PointBuild_left_count(chunk_end, left_end, j);
    float4 xp = x_plane[j];
    int x_axis = as_int(xp.y);
    int x_base = child_base + 2 * slots + 2 * j;
    __global int8 *cls = classes + 2 * j, *x_cls = classes + 2 * slots + 2 * j;
    BuildNode l, r;
    PointBuild_sides(&nd, (PointBuildPlane){nd.axis, nd.split}, &l, &r);
    if (x_axis < 0) {
        l.start = nd.start;
        l.count = n_left;
        r.start = nd.start + n_left;
        r.count = nd.count - n_left;
        PointBuild_store_children(nodes, id, child_base + 2 * j, l, r, nd.depth);
        PointBuild_store_holes(nodes, x_base);
        cls[0] = PointBuild_class(l.count, nd.depth + 1, max_depth);
        cls[1] = PointBuild_class(r.count, nd.depth + 1, max_depth);
        x_cls[0] = x_cls[1] = (int8)(0);
        return;
    }
    /* an empty-space cut: an empty leaf and X, which holds every point and
     * is split by x_plane */
    bool x_right = as_int(xp.z) != 0;
    l.start = r.start = nd.start;
    l.count = x_right ? 0 : nd.count;
    r.count = x_right ? nd.count : 0;
    PointBuild_store_children(nodes, id, child_base + 2 * j, l, r, nd.depth);
    int xid = child_base + 2 * j + (x_right ? 1 : 0);
    BuildNode x = x_right ? r : l;
    x.depth = nd.depth + 1;
    PointBuildPlane xs = (PointBuildPlane){x_axis, xp.x};
    BuildNode xl, xr;
    PointBuild_sides(&x, xs, &xl, &xr);
    xl.start = nd.start;
    xl.count = n_left;
    xr.start = nd.start + n_left;
    xr.count = nd.count - n_left;
    PointBuild_store_children(nodes, xid, x_base, xl, xr, x.depth);
    nodes[xid].axis = xs.axis;
    nodes[xid].split = xs.split;
    cls[0] = cls[1] = (int8)(0);
    x_cls[0] = PointBuild_class(xl.count, x.depth + 1, max_depth);
    x_cls[1] = PointBuild_class(xr.count, x.depth + 1, max_depth);
}

/* Over the level's `slots`: the active nodes split, the slots past them
 * holes of class 0. */
__kernel void PointBuild_large_split(const __global int *active, __global BuildNode *nodes,
                                const __global int *chunk_end, const __global int *left_end,
                                const __global float4 *x_plane, const int child_base, const int max_depth,
                                __global int8 *classes, const __global int *active_count, const int slots) {
    int j = Launch_global_id();
    if (j >= slots) return;
    if (j < active_count[0]) {
        PointBuild_large_split_at(j, active, nodes, chunk_end, left_end, x_plane, child_base, max_depth, classes,
                                  slots);
        return;
    }
    PointBuild_store_holes(nodes, child_base + 2 * j);
    PointBuild_store_holes(nodes, child_base + 2 * slots + 2 * j);
    classes[2 * j] = classes[2 * j + 1] = (int8)(0);
    classes[2 * slots + 2 * j] = classes[2 * slots + 2 * j + 1] = (int8)(0);
}

/* Stable partition of each chunk's points to the two sides of its node's
 * partition plane (its children's, or after a cut its X's, segments). */
inline void PointBuild_chunk_scatter_at(int c, const __global Chunk *chunks, const __global int *active,
                                       const __global BuildNode *nodes, const __global float4 *x_plane,
                                       const __global float4 *pts, __global float4 *out,
                                       const __global int *chunk_left, const __global int *left_end,
                                       const __global int *chunk_end) {
    Chunk ch = chunks[c];
    BuildNode nd = nodes[active[ch.slot]];
    int first = c - ch.rank;
    int left_before = (left_end[c] - chunk_left[c]) - (first > 0 ? left_end[first - 1] : 0);
    int right_before = ch.rank * POINT_BUILD_CHUNK - left_before;
    int n_left = PointBuild_left_count(chunk_end, left_end, ch.slot);
    PointBuildPlane plane = PointBuild_partition(&nd, x_plane[ch.slot]);
    for (int i = 0; i < ch.count; ++i) {
        float4 p = pts[ch.start + i];
        if (PointBuild_goes_left(plane, nd.count, p, ch.rank * POINT_BUILD_CHUNK + i))
            out[nd.start + left_before++] = p;
        else
            out[nd.start + n_left + right_before++] = p;
    }
}

__kernel void PointBuild_chunk_scatter(const __global Chunk *chunks, const __global int *active,
                                  const __global BuildNode *nodes, const __global float4 *x_plane,
                                  const __global float4 *pts, __global float4 *out,
                                  const __global int *chunk_left, const __global int *left_end,
                                  const __global int *chunk_end, const __global int *active_count) {
    int c = Launch_global_id();
    if (c < PointBuild_chunk_total(chunk_end, active_count[0]))
        PointBuild_chunk_scatter_at(c, chunks, active, nodes, x_plane, pts, out, chunk_left, left_end, chunk_end);
}

/* The new nodes (base + i) into the next level's large list, with its
 * chunks (chunk_end: their inclusive scan), and the small roots' list, in
 * order, at the exclusive prefix sums of their classes. A node that
 * leaves the large stage (a small root, a leaf with points) has its points
 * copied from `from`, the array the level partitioned into, to `to`, the
 * one the next level partitions into: both hold them from then on. */
inline void PointBuild_list_node(int id, int8 c, int8 at, const __global BuildNode *nodes,
                                 const __global float4 *from, __global float4 *to, __global int *large,
                                 __global int *small, __global int *chunk_end, __global Chunk *chunks) {
    BuildNode nd = nodes[id];
    if (c.s0) {
        large[at.s0] = id;
        chunk_end[at.s0] = at.s2 + c.s2;
        PointBuild_write_chunks(chunks, at.s2, c.s2, at.s0, nd.start, nd.count);
        return;
    }
    if (c.s1) small[at.s1] = id;
    if (nd.left < 0 && nd.count > 0)
        for (int k = nd.start; k < nd.start + nd.count; ++k) to[k] = from[k];
}

__kernel void PointBuild_lists(const __global int8 *classes, const __global int8 *scanned, const int base,
                               const int n, const __global BuildNode *nodes, const __global float4 *from,
                               __global float4 *to, __global int *large, __global int *small,
                               __global int *chunk_end, __global Chunk *chunks) {
    int i = Launch_global_id();
    if (i < n) PointBuild_list_node(base + i, classes[i], scanned[i], nodes, from, to, large, small, chunk_end, chunks);
}

/* ---- small-node stage ---------------------------------------------------- */

/* Per small root: tight box as its cell, full mask, the left-side mask of
 * every candidate plane (3 axes x its points; ties ordered by index), and
 * an estimate of the radius holding k_hint points, from the box's measure
 * in as many dimensions as the points spread (radius < 0: no estimate). */
inline void PointBuild_small_root_at(int r, const __global int *roots, __global BuildNode *nodes,
                                    const __global float4 *pts, __global uint *masks, __global float *radius,
                                    float k_hint) {
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
        SortSmall_coordinate((const __global float *)(pts + nd.start) + a, n, c, order);
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

__kernel void PointBuild_small_roots(const __global int *roots, __global BuildNode *nodes,
                                const __global float4 *pts, __global uint *masks,
                                __global float *radius, const float k_hint, const int n_roots) {
    int r = Launch_global_id();
    if (r < n_roots) PointBuild_small_root_at(r, roots, nodes, pts, masks, radius, k_hint);
}

/* Per active small node: the candidate plane of least VVH cost
 *   C_t + (n_L (V_L grown by R) + n_R (V_R grown by R)) / (V grown by R);
 * boxes differ only along the split axis, so the volumes reduce to lengths.
 * The node splits when the cost is below its point count (the cost of
 * scanning it as a leaf); cand = 1 + the chosen point's index, 0 for a leaf. */
inline void PointBuild_small_decide_at(int j, const __global int *active, __global BuildNode *nodes,
                                      const __global float4 *pts, const __global uint *masks, float radius,
                                      float cost_traverse, int max_depth, __global int *split_flag,
                                      __global int *cand) {
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

__kernel void PointBuild_small_decide(const __global int *active, __global BuildNode *nodes,
                                 const __global float4 *pts, const __global uint *masks,
                                 const float radius, const float cost_traverse,
                                 const int max_depth, __global int *split_flag,
                                 __global int *cand, const int n_active) {
    int j = Launch_global_id();
    if (j < n_active)
        PointBuild_small_decide_at(j, active, nodes, pts, masks, radius, cost_traverse, max_depth, split_flag, cand);
}

/* Children of the splitting small nodes (indices into the active list) at
 * child_base + 2 j: the masks of both sides and the cell cut at the plane.
 * Every child is active on the next level (small_decide makes leaves). */
inline void PointBuild_small_split_at(int j, int slot, const __global int *active, __global BuildNode *nodes,
                                     const __global int *cand, const __global uint *masks, int child_base,
                                     __global int *next_active) {
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

__kernel void PointBuild_small_split(const __global int *splitting, const __global int *active,
                                __global BuildNode *nodes, const __global int *cand,
                                const __global uint *masks, const int child_base,
                                __global int *next_active, const int n_split) {
    int j = Launch_global_id();
    if (j < n_split) PointBuild_small_split_at(j, splitting[j], active, nodes, cand, masks, child_base, next_active);
}

/* ---- output stage -------------------------------------------------------- */

/* i-th point of a leaf: its place in the working array. */
inline int PointBuild_leaf_point(const BuildNode *nd, uint *rest, int i) {
    if (nd->root < 0) return nd->start + i;
    int k = 31 - clz(*rest);
    *rest &= ~(1u << k);
    return nd->start + k;
}

/* Subtree size and photon sums of node id: from the points at a leaf and
 * from the two children (done already) otherwise. */
inline void PointBuild_node_sums(int id, const __global BuildNode *nodes, const __global float4 *pts,
                                 const __global float4 *power, const __global float4 *dir,
                                 const __global float4 *normal, int has_photons, __global int *size,
                                 __global BuildSums *sums) {
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

/* Bottom-up over one batch of nodes (their children live in later
 * batches, but for the children of cut-off parts X, ids x_first to x_end
 * - 1, which the same pass made: X's work item does them first). */
inline void PointBuild_sums_at(int id, const __global BuildNode *nodes, const __global float4 *pts,
                               const __global float4 *power, const __global float4 *dir,
                               const __global float4 *normal, int has_photons, __global int *size,
                               __global BuildSums *sums, int x_first, int x_end) {
    int left = nodes[id].left;
    if (nodes[id].count < 0) return; /* a hole */
    if (left >= x_first && left < x_end) {
        PointBuild_node_sums(left, nodes, pts, power, dir, normal, has_photons, size, sums);
        PointBuild_node_sums(left + 1, nodes, pts, power, dir, normal, has_photons, size, sums);
    }
    PointBuild_node_sums(id, nodes, pts, power, dir, normal, has_photons, size, sums);
}

__kernel void PointBuild_sums(const __global BuildNode *nodes, const __global float4 *pts,
                         const __global float4 *power, const __global float4 *dir,
                         const __global float4 *normal, const int has_photons,
                         __global int *size, __global BuildSums *sums, const int base,
                         const int n, const int x_first, const int x_end) {
    int i = Launch_global_id();
    if (i < n) PointBuild_sums_at(base + i, nodes, pts, power, dir, normal, has_photons, size, sums, x_first, x_end);
}

/* Preorder address and first point of both children of node id (inner). */
inline void PointBuild_child_order(int id, int left, const __global BuildNode *nodes, const __global int *size,
                                   __global int *addr, __global int *first) {
    addr[left] = addr[id] + 1;
    addr[left + 1] = addr[id] + 1 + size[left];
    first[left] = first[id];
    first[left + 1] = first[id] + nodes[left].count;
}

/* Top-down over one batch: the children's preorder addresses and first
 * points of every inner node (the root's are 0, set by the host), and of
 * the children of X's children (ids x_first to x_end - 1: made in the same
 * pass, so in no batch of their own). */
inline void PointBuild_preorder_at(int id, const __global BuildNode *nodes, const __global int *size,
                                   __global int *addr, __global int *first, int x_first, int x_end) {
    int left = nodes[id].left;
    if (left < 0) return;
    PointBuild_child_order(id, left, nodes, size, addr, first);
    if (left < x_first || left >= x_end) return;
    for (int c = left; c < left + 2; ++c) {
        int grand = nodes[c].left;
        if (grand >= 0) PointBuild_child_order(c, grand, nodes, size, addr, first);
    }
}

__kernel void PointBuild_preorder(const __global BuildNode *nodes, const __global int *size,
                             __global int *addr, __global int *first, const int base,
                             const int n, const int x_first, const int x_end) {
    int i = Launch_global_id();
    if (i < n) PointBuild_preorder_at(base + i, nodes, size, addr, first, x_first, x_end);
}

/* Every node to its preorder slot: the traversal node, the payload with
 * E~_p = max(0, n_p . sum_i w_i Phi_i) / r_p^2 (r_p the largest extent of the
 * tight box, at least `radius`), and a leaf's points (and photon
 * attributes) to leaf order. */
inline void PointBuild_emit_at(int id, const __global BuildNode *nodes, const __global BuildSums *sums,
                               const __global int *addr, const __global int *first, const __global float4 *pts,
                               const __global float4 *power, const __global float4 *dir,
                               const __global float4 *normal, int has_photons, float radius,
                               __global KdNode *out_nodes, __global PointNode *out_info, __global float4 *out_pts,
                               __global float4 *out_power, __global float4 *out_dir, __global float4 *out_normal) {
    BuildNode nd = nodes[id];
    if (nd.count < 0) return; /* a hole */
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

__kernel void PointBuild_emit(const __global BuildNode *nodes, const __global BuildSums *sums,
                         const __global int *addr, const __global int *first,
                         const __global float4 *pts, const __global float4 *power,
                         const __global float4 *dir, const __global float4 *normal,
                         const int has_photons, const float radius, __global KdNode *out_nodes,
                         __global PointNode *out_info, __global float4 *out_pts,
                         __global float4 *out_power, __global float4 *out_dir,
                         __global float4 *out_normal, const int n) {
    int id = Launch_global_id();
    if (id < n)
        PointBuild_emit_at(id, nodes, sums, addr, first, pts, power, dir, normal, has_photons, radius, out_nodes,
                           out_info, out_pts, out_power, out_dir, out_normal);
}

/* ---- the whole build in one launch -------------------------------------- */

/* Slots of the batch list: the root's, one a level (a level deepens every
 * node it keeps, so there are at most POINT_TREE_MAX_DEPTH of each stage). */
#define BUILD_SERIAL_BATCHES (2 * POINT_TREE_MAX_DEPTH + 2)

/* The median of the finite, positive values among v[0..n), which it
 * reorders (an insertion sort of those, in front); 0 where there is none. */
inline float PointBuild_median_estimate(__global float *v, int n) {
    int m = 0;
    for (int i = 0; i < n; ++i) {
        float e = v[i];
        if (!(isfinite(e) && e > 0.0f)) continue;
        int k = m++;
        while (k > 0 && v[k - 1] > e) {
            v[k] = v[k - 1];
            k--;
        }
        v[k] = e;
    }
    if (m == 0) return 0.0f;
    return m % 2 ? v[m / 2] : (v[m / 2 - 1] + v[m / 2]) / 2.0f;
}

/* The indices 0..n-1 a work-item of the group takes: its own, then every
 * group size further (all of them for a group of one). */
#define POINT_BUILD_EACH(j, n) for (int j = (int)get_local_id(0); j < (n); j += (int)get_local_size(0))
/* The group's writes so far seen by all of it. */
#define POINT_BUILD_SYNC() barrier(CLK_LOCAL_MEM_FENCE | CLK_GLOBAL_MEM_FENCE)

/* What the group of PointBuild_serial shares: the node count, the batch
 * count, the small roots and active large nodes, the nodes a small level
 * splits, and the search radius. Its first work-item writes them. */
typedef struct {
    int count, batches, roots, active, split;
    float radius;
} PointBuildShared;

/* The build of point_tree_build.py (_Build) in one launch by one
 * work-group (of one work-item on a CPU device): its level loops run here
 * in order, each level's steps over nodes and chunks shared among the
 * group (the steps the launched build runs per node and per chunk, each
 * index independent of the others), its scans and lists' offsets by the
 * group's first work-item, so that the node table, its batches and the
 * tree are the same bit for bit. For small point sets, where each launch of
 * the level-by-level build costs far more than its work. The root is in
 * nodes[0] and the points in work[0..n) (n > 1). Scratch, in the host's
 * layout (_serial_build): `ints` holds the active large nodes and their
 * chunk_end (L each), chunk_left and left_end (B each), the small roots,
 * the small stage's flags, candidates and two active lists (n each), then
 * size, addr and first (capacity each); `f4` x_plane (L), chunk_lo and
 * chunk_hi (B); `classes` and `class_at` a level's new nodes' classes and
 * their exclusive prefix sums (4 L each). result: 0 or 1 when the node
 * table (capacity) or the batch list ran out of room, then the node count,
 * large and small levels, small roots and the radius (float bits). */
__kernel void PointBuild_serial(const int n, const int L, const int B, const int capacity, const float empty_ratio,
                                const int max_depth, const float k_hint, const float given_radius,
                                const float cost_traverse, __global BuildNode *nodes, __global float4 *work,
                                __global float4 *scratch, __global Chunk *chunks, __global int8 *classes,
                                __global int8 *class_at, __global int *ints, __global float4 *f4,
                                __global uint *masks, __global float *root_radius, __global int4 *batches,
                                __global BuildSums *sums, const int has_photons, const __global float4 *power,
                                const __global float4 *dir, const __global float4 *normal,
                                __global KdNode *out_nodes, __global PointNode *out_info, __global float4 *out_pts,
                                __global float4 *out_power, __global float4 *out_dir, __global float4 *out_normal,
                                __global int *result) {
    __local PointBuildShared s;
    bool lead = get_local_id(0) == 0;
    __global int *active = ints, *chunk_end = active + L, *chunk_left = chunk_end + L, *left_end = chunk_left + B;
    __global int *roots = left_end + B, *flag = roots + n, *cand = flag + n, *small_a = cand + n;
    __global int *small_b = small_a + n, *size = small_b + n, *addr = size + capacity, *first = addr + capacity;
    __global float4 *x_plane = f4, *chunk_lo = x_plane + L, *chunk_hi = chunk_lo + B;
    int large_levels = 0, small_levels = 0;
    if (lead) {
        s.count = 1;
        s.batches = 1;
        s.roots = 0;
        s.active = 0;
        batches[0] = (int4)(0, 1, 0, 0);
        result[0] = 1;
        /* large-node stage (_Build.large_stage) */
        if (n > POINT_BUILD_SMALL) {
            s.active = 1;
            active[0] = 0;
            chunk_end[0] = (n + POINT_BUILD_CHUNK - 1) / POINT_BUILD_CHUNK;
            PointBuild_write_chunks(chunks, 0, chunk_end[0], 0, nodes[0].start, nodes[0].count);
        } else {
            roots[s.roots++] = 0;
        }
    }
    POINT_BUILD_SYNC();
    while (s.active) {
        int n_active = s.active, base = s.count, n_roots = s.roots;
        large_levels++;
        int total = PointBuild_chunk_total(chunk_end, n_active), fresh = 4 * n_active;
        if (base + fresh > capacity || s.batches == BUILD_SERIAL_BATCHES) return;
        POINT_BUILD_EACH(c, total) PointBuild_chunk_bounds_at(c, chunks, work, chunk_lo, chunk_hi);
        POINT_BUILD_SYNC();
        POINT_BUILD_EACH(j, n_active)
            PointBuild_large_decide_at(j, active, nodes, chunk_end, chunk_lo, chunk_hi, empty_ratio, max_depth,
                                       x_plane);
        POINT_BUILD_SYNC();
        POINT_BUILD_EACH(c, total)
            chunk_left[c] = PointBuild_chunk_count_left_at(c, chunks, active, nodes, x_plane, work);
        POINT_BUILD_SYNC();
        if (lead) {
            int run = 0;
            for (int c = 0; c < total; ++c) {
                run += chunk_left[c];
                left_end[c] = run;
            }
        }
        POINT_BUILD_SYNC();
        POINT_BUILD_EACH(j, n_active)
            PointBuild_large_split_at(j, active, nodes, chunk_end, left_end, x_plane, base, max_depth, classes,
                                      n_active);
        POINT_BUILD_SYNC();
        POINT_BUILD_EACH(c, total)
            PointBuild_chunk_scatter_at(c, chunks, active, nodes, x_plane, work, scratch, chunk_left, left_end,
                                        chunk_end);
        POINT_BUILD_SYNC();
        __global float4 *swap = work;
        work = scratch;
        scratch = swap;
        /* the next level's lists at the classes' exclusive prefix sums (the
         * lists of this level are read no more) */
        if (lead) {
            batches[s.batches++] = (int4)(base, 2 * n_active, base + 2 * n_active, base + fresh);
            int8 at = (int8)(0);
            for (int i = 0; i < fresh; ++i) {
                class_at[i] = at;
                at += classes[i];
            }
            s.count = base + fresh;
            s.roots = n_roots + at.s1;
            s.active = at.s0;
        }
        POINT_BUILD_SYNC();
        POINT_BUILD_EACH(i, fresh)
            PointBuild_list_node(base + i, classes[i], class_at[i], nodes, work, scratch, active, roots + n_roots,
                                 chunk_end, chunks);
        POINT_BUILD_SYNC();
    }
    /* small-node stage (_Build.small_stage) */
    int n_roots = s.roots;
    POINT_BUILD_EACH(r, n_roots) PointBuild_small_root_at(r, roots, nodes, work, masks, root_radius, k_hint);
    POINT_BUILD_SYNC();
    if (lead) s.radius = given_radius >= 0.0f ? given_radius : PointBuild_median_estimate(root_radius, n_roots);
    POINT_BUILD_SYNC();
    float radius = s.radius;
    __global int *act = roots, *next = small_a;
    int n_active = n_roots;
    while (n_active) {
        small_levels++;
        POINT_BUILD_EACH(j, n_active)
            PointBuild_small_decide_at(j, act, nodes, work, masks, radius, cost_traverse, max_depth, flag, cand);
        POINT_BUILD_SYNC();
        if (lead) {
            int n_split = 0;
            for (int j = 0; j < n_active; ++j)
                if (flag[j]) flag[n_split++] = j;
            s.split = n_split;
        }
        POINT_BUILD_SYNC();
        int n_split = s.split, base = s.count;
        if (!n_split) break;
        if (base + 2 * n_split > capacity || s.batches == BUILD_SERIAL_BATCHES) return;
        POINT_BUILD_EACH(j, n_split) PointBuild_small_split_at(j, flag[j], act, nodes, cand, masks, base, next);
        POINT_BUILD_SYNC();
        if (lead) {
            batches[s.batches++] = (int4)(base, 2 * n_split, 0, 0);
            s.count = base + 2 * n_split;
        }
        POINT_BUILD_SYNC();
        act = next;
        next = next == small_a ? small_b : small_a;
        n_active = 2 * n_split;
    }
    /* output stage (_Build.output_stage) */
    int count = s.count, n_batches = s.batches;
    for (int b = n_batches - 1; b >= 0; --b) {
        int4 t = batches[b];
        POINT_BUILD_EACH(i, t.y)
            PointBuild_sums_at(t.x + i, nodes, work, power, dir, normal, has_photons, size, sums, t.z, t.w);
        POINT_BUILD_SYNC();
    }
    POINT_BUILD_EACH(i, count) addr[i] = first[i] = 0;
    POINT_BUILD_SYNC();
    for (int b = 0; b < n_batches; ++b) {
        int4 t = batches[b];
        POINT_BUILD_EACH(i, t.y) PointBuild_preorder_at(t.x + i, nodes, size, addr, first, t.z, t.w);
        POINT_BUILD_SYNC();
    }
    POINT_BUILD_EACH(id, count)
        PointBuild_emit_at(id, nodes, sums, addr, first, work, power, dir, normal, has_photons, radius, out_nodes,
                           out_info, out_pts, out_power, out_dir, out_normal);
    if (lead) {
        result[0] = 0;
        result[1] = size[0];
        result[2] = large_levels;
        result[3] = small_levels;
        result[4] = n_roots;
        result[5] = as_int(radius);
    }
}
