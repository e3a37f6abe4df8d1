"""Point kd-tree of a photon map: build on the device, k-nearest-neighbour
queries and density estimation of irradiance.

``PointTree.build(device, points)`` builds the tree ([ZHWG08] for points,
VVH cost); ``knn(queries, k, max_radius)`` returns ``(indices,
squared_distances)`` as ``(M, k)`` arrays sorted by distance, padded with
``-1`` and ``inf``. With photon attributes (power, incident direction,
surface normal) the tree also estimates irradiance, and every node carries
what the illumination cut reads (bounds, count, summed power,
representative normal, approximate irradiance E~_p).
"""

from __future__ import annotations

import time

import numpy as np
import pyopencl as cl
import pyopencl.array as cla

from ..device import Device
from ..layout import KDNODE_DTYPE
from .kernels import Kernels
from .layout import POINT_NODE_DTYPE
from .point_tree_build import GROUP, BuildParams, BuiltTree, build, points_on_device

FILTERS = {"box": 0, "cone": 1, "epanechnikov": 2}
MAX_K = 1024  # the candidate list lives in private memory
_ROWS_PER_LAUNCH = 1 << 21  # queries per kNN launch


def _as_points(array, name: str) -> np.ndarray:
    """``array`` as contiguous (N, 3) float32, finite."""
    out = np.ascontiguousarray(np.asarray(array, np.float32).reshape(-1, 3))
    if not np.isfinite(out).all():
        raise ValueError(f"{name} contain NaN or Inf")
    return out


def _spatial_order(points: np.ndarray) -> np.ndarray:
    """A permutation visiting ``points`` along a Morton curve, so that
    neighbouring work items search neighbouring parts of the tree."""
    lo = points.min(axis=0)
    scale = 1023.0 / np.maximum(points.max(axis=0) - lo, 1e-30)
    cells = ((points - lo) * scale).astype(np.uint32)

    def spread(v):
        v = (v | (v << 16)) & 0x030000FF
        v = (v | (v << 8)) & 0x0300F00F
        v = (v | (v << 4)) & 0x030C30C3
        return (v | (v << 2)) & 0x09249249

    code = spread(cells[:, 0]) | (spread(cells[:, 1]) << 1) | (spread(cells[:, 2]) << 2)
    return np.argsort(code, kind="stable")


def _global(n: int) -> tuple[int]:
    """Global size for ``n`` bound-checked work items in groups of GROUP."""
    return (-(-n // GROUP) * GROUP,)


def _float4(array: np.ndarray) -> np.ndarray:
    out = np.zeros((len(array), 4), np.float32)
    out[:, :3] = array
    return out


class PointTree:
    """A point kd-tree on one device, ready for kNN and density queries."""

    def __init__(self, device: Device, built: BuiltTree, point_count: int, build_ms: float):
        self.device = device
        self._built = built
        self.point_count = point_count
        self.node_count = built.node_count
        self.radius = built.radius  # the VVH search radius the tree was built for
        self.has_photons = built.power is not None
        self.stats = dict(built.stats)
        self.stats["ms"] = dict(built.stats["ms"], build=build_ms)

    @classmethod
    def build(
        cls,
        device: Device,
        points: np.ndarray,
        power: np.ndarray | None = None,
        directions: np.ndarray | None = None,
        normals: np.ndarray | None = None,
        k_hint: float = 50.0,
        radius: float | None = None,
        **knobs,
    ) -> "PointTree":
        """Build over ``points`` (N, 3). Photon attributes, all or none:
        ``power`` (N, 3) rgb, ``directions`` (N, 3) unit incident directions
        pointing back along the photon's path, ``normals`` (N, 3) surface
        normals on the side it arrived. ``k_hint`` / ``radius``: the k or the
        search radius the VVH cost is tuned for (radius estimated if None).
        ``knobs``: cost_traverse, empty_ratio, max_depth (see BuildParams)."""
        pts = _as_points(points, "points")
        given = [a is not None for a in (power, directions, normals)]
        if any(given) and not all(given):
            raise ValueError("photon power, directions and normals go together")
        photons = None
        if all(given):
            photons = tuple(_float4(_as_points(a, name)) for a, name in ((power, "power"), (directions, "directions"), (normals, "normals")))
            if any(len(a) != len(pts) for a in photons):
                raise ValueError("photon attributes must have one row per point")
        queue = device.queue
        on_device = points_on_device(queue, pts)
        if photons is not None:
            photons = tuple(cla.to_device(queue, a) for a in photons)
        return cls.from_device(device, on_device, photons, k_hint=k_hint, radius=radius, **knobs)

    @classmethod
    def from_device(
        cls, device: Device, points: cla.Array, photons: tuple | None = None, k_hint: float = 50.0,
        radius: float | None = None, **knobs,
    ) -> "PointTree":
        """Build over device arrays: ``points`` (N, 4) float32 with each
        point's index in w (int bits), ``photons`` None or (power,
        directions, normals) as (N, 4) float32 arrays in index order."""
        if not np.isfinite(k_hint) or k_hint < 1:
            raise ValueError(f"k_hint must be at least 1, not {k_hint}")
        params = BuildParams(k_hint=float(k_hint), radius=radius, **knobs)
        start = time.perf_counter()
        built = build(device, points, photons, params)
        return cls(device, built, len(points), (time.perf_counter() - start) * 1e3)

    # -- device arguments -------------------------------------------------

    def kernel_args(self) -> list:
        """Arguments matching POINT_TREE_PARAMS in kernels/point_tree.h, in order."""
        return [self._built.nodes.data, self._built.points.data]

    def photon_args(self) -> list:
        """Arguments matching PHOTON_PARAMS (photon attributes in leaf order)."""
        if not self.has_photons:
            raise ValueError("this tree was built without photon attributes")
        b = self._built
        return [b.power.data, b.direction.data, b.normal.data]

    @property
    def node_buffer(self) -> cl.Buffer:
        """PointNode payloads in preorder (what the illumination cut reads)."""
        return self._built.info.data

    # -- host copies for tests and statistics -----------------------------

    def nodes(self) -> np.ndarray:
        """Traversal nodes (KdNode) in preorder."""
        return self._built.nodes.get()

    def node_info(self) -> np.ndarray:
        """PointNode payloads in preorder (POINT_NODE_DTYPE)."""
        return self._built.info.get()

    def positions(self) -> np.ndarray:
        """(N, 3) float32 point positions in leaf order."""
        return self._built.points.get()[: self.point_count, :3].copy()

    def photons(self) -> dict[str, np.ndarray]:
        """Photon attributes in leaf order: "power", "direction", "normal", each (N, 3)."""
        if not self.has_photons:
            raise ValueError("this tree was built without photon attributes")
        b, n = self._built, self.point_count
        return {name: a.get()[:n, :3].copy() for name, a in (("power", b.power), ("direction", b.direction), ("normal", b.normal))}

    def leaf_order(self) -> np.ndarray:
        """Original index of the point at each place of the leaf order."""
        return self._built.points.get()[: self.point_count, 3].copy().view(np.int32)

    # -- queries ------------------------------------------------------------

    def _kernels(self, k: int) -> Kernels:
        return Kernels(self.device.program("point_tree_query.cl", {"KNN_K": k}))

    @staticmethod
    def _max_d2(max_radius) -> np.float32:
        if max_radius is None:
            return np.float32(np.inf)
        r = float(max_radius)
        if not r >= 0:
            raise ValueError(f"max_radius must be >= 0, not {max_radius}")
        return np.float32(min(r * r, np.finfo(np.float32).max)) if np.isfinite(r) else np.float32(np.inf)

    @staticmethod
    def _check_k(k) -> int:
        k = int(k)
        if not 1 <= k <= MAX_K:
            raise ValueError(f"k must be in 1..{MAX_K}, not {k}")
        return k

    def knn(self, queries: np.ndarray, k: int, max_radius: float | None = None):
        """The ``k`` nearest points of each query within ``max_radius``:
        ``(indices int32, squared_distances float32)``, both (M, k), sorted by
        distance, padded with -1 and inf."""
        k = self._check_k(k)
        q3 = _as_points(queries, "queries")
        m = len(q3)
        idx = np.empty((m, k), np.int32)
        d2 = np.empty((m, k), np.float32)
        if m == 0:
            return idx, d2
        dev = self.device
        kernel = self._kernels(k).PointTree_knn_batch
        max_d2 = self._max_d2(max_radius)
        # batches of whole rows that fit one device allocation
        rows = max(1, min(m, dev.max_alloc_bytes // (8 * k), _ROWS_PER_LAUNCH))
        out_i = dev.empty(min(rows, m) * k * 4)
        out_d = dev.empty(min(rows, m) * k * 4)
        for s in range(0, m, rows):
            n = min(rows, m - s)
            part = q3[s : s + n]
            kernel(
                dev.queue, _global(n), (GROUP,), *self.kernel_args(), dev.buffer(_float4(part)),
                dev.buffer(_spatial_order(part).astype(np.int32)), max_d2, np.int32(n), out_i, out_d,
            )
            cl.enqueue_copy(dev.queue, idx[s : s + n], out_i)
            cl.enqueue_copy(dev.queue, d2[s : s + n], out_d)
        return idx, d2

    def irradiance(
        self,
        positions: np.ndarray,
        normals: np.ndarray,
        k: int,
        max_radius: float | None = None,
        filter: str = "epanechnikov",
        normal_cos: float = 0.5,
    ) -> np.ndarray:
        """Irradiance (M, 3) in W/m^2 at surface points with unit ``normals``,
        from the ``k`` nearest photons (within ``max_radius``) and a
        ``filter`` ("box", "cone" or "epanechnikov"). Photons from behind the
        surface, or stored where the normal differs by more than
        acos(normal_cos), are left out."""
        return self._density(positions, normals, None, k, max_radius, filter, normal_cos)

    def radiance(
        self,
        positions: np.ndarray,
        normals: np.ndarray,
        albedo: np.ndarray,
        k: int,
        max_radius: float | None = None,
        filter: str = "epanechnikov",
        normal_cos: float = 0.5,
    ) -> np.ndarray:
        """Outgoing radiance (M, 3) of Lambertian surfaces with ``albedo``
        (M, 3): albedo / pi times the irradiance estimate."""
        return self._density(positions, normals, albedo, k, max_radius, filter, normal_cos)

    def _density(self, positions, normals, albedo, k, max_radius, filter, normal_cos) -> np.ndarray:
        k = self._check_k(k)
        if filter not in FILTERS:
            raise ValueError(f"filter must be one of {sorted(FILTERS)}, not {filter!r}")
        photon_args = self.photon_args()
        pos = _float4(_as_points(positions, "positions"))
        nrm = _float4(_as_points(normals, "normals"))
        if len(nrm) != len(pos):
            raise ValueError("one normal per position")
        alb = _float4(_as_points(albedo, "albedo")) if albedo is not None else np.zeros((1, 4), np.float32)
        if albedo is not None and len(alb) != len(pos):
            raise ValueError("one albedo per position")
        m = len(pos)
        out = np.zeros((m, 4), np.float32)
        if m == 0:
            return out[:, :3]
        dev = self.device
        buf = dev.empty(out.nbytes)
        order = _spatial_order(pos[:, :3]).astype(np.int32)
        self._kernels(k).PointTree_density_batch(
            dev.queue, _global(m), (GROUP,), *self.kernel_args(), *photon_args, dev.buffer(pos), dev.buffer(nrm),
            dev.buffer(alb), dev.buffer(order), self._max_d2(max_radius), np.int32(FILTERS[filter]),
            np.float32(normal_cos), np.int32(albedo is not None), np.int32(m), buf,
        )
        cl.enqueue_copy(dev.queue, out, buf)
        return out[:, :3]


__all__ = ["PointTree", "FILTERS", "KDNODE_DTYPE", "POINT_NODE_DTYPE"]
