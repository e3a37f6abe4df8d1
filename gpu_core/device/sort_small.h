/* Sorting the few elements of one small node in one work-item, as the
 * kd-tree builders' small-node stages do. */
#ifndef GPUGI_SORT_SMALL_H
#define GPUGI_SORT_SMALL_H

/* Value x of element e into the first i values of c, kept ascending with
 * their elements in `order`, after any equal ones (an insertion sort's step). */
inline void SortSmall_insert(float *c, int *order, int i, float x, int e) {
    int k = i;
    while (k > 0 && c[k - 1] > x) {
        c[k] = c[k - 1];
        order[k] = order[k - 1];
        k--;
    }
    c[k] = x;
    order[k] = e;
}

/* The n values v[4 i] (one coordinate of n float4) sorted into c,
 * ascending, with their element numbers in `order` (a stable insertion
 * sort: ties by element number). */
inline void SortSmall_coordinate(const __global float *v, int n, float *c, int *order) {
    for (int i = 0; i < n; ++i) SortSmall_insert(c, order, i, v[4 * i], i);
}

/* The same for the n values v[4 seq[i]], inserted in the order of seq
 * (ties in that order): few moves where seq nearly sorts them already. */
inline void SortSmall_coordinate_in(const __global float *v, int n, const int *seq, float *c, int *order) {
    for (int i = 0; i < n; ++i) SortSmall_insert(c, order, i, v[4 * seq[i]], seq[i]);
}

#endif
