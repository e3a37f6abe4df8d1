"""Acceleration structures of [ZHWG08], built on the device: the triangle
kd-tree that every ray traverses, and the point kd-tree (VVH cost) of the
photon maps, the illumination cut and the k-means centres, with kNN and
density estimation."""
