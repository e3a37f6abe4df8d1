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

import numpy as np
import pyopencl as cl
import pyopencl.array as cla

from ..device import Device
from ..device.constants import PHOTON_FILTER_BOX, PHOTON_FILTER_CONE, PHOTON_FILTER_EPANECHNIKOV
from ..device.layout import KDNODE_DTYPE, POINT_NODE_DTYPE, finite_rows, float4_rows
from ..device.timer import StageTimer
from .point_tree_build import BuildParams, BuiltTree, build, points_on_device

FILTERS = {"box": PHOTON_FILTER_BOX, "cone": PHOTON_FILTER_CONE, "epanechnikov": PHOTON_FILTER_EPANECHNIKOV}
DENSITY_FILTER = "epanechnikov"  # the density estimates' filter, unless told
DENSITY_NORMAL_COS = 0.5  # photons stored on surfaces turned further away from the point's do not count
MAX_K = 1024  # the candidate list lives in private memory
_ROWS_PER_LAUNCH = 1 << 21  # queries per kNN launch
_PROGRAM = "accel/point_tree_query.cl"


def knn_capacity(k: int) -> int:
    """The kNN heap's capacity a program is built with for searches of
    ``k`` points (KNN_K): the next power of two from 16. Searches keep their
    own k (KNN_VARIABLE_K), so the k of every preset, or of a slider being
    dragged, finds one of a few programs built already."""
    return max(16, 1 << (max(int(k), 1) - 1).bit_length())


def query_defines(k: int) -> dict:
    """The query program's defines for searches of ``k`` neighbours."""
    return {"KNN_K": knn_capacity(k), "KNN_VARIABLE_K": 1}


def query_programs(k: int) -> list[tuple[str, dict]]:
    """The query program for searches of ``k`` neighbours (for building it up front)."""
    return [(_PROGRAM, query_defines(k))]


def search_d2(max_radius: float | None) -> np.float32:
    """The squared search radius the query kernels take for ``max_radius``
    (None: unbounded)."""
    if max_radius is None:
        return np.float32(np.inf)
    r = float(max_radius)
    if not r >= 0:
        raise ValueError(f"max_radius must be >= 0, not {max_radius}")
    return np.float32(min(r * r, np.finfo(np.float32).max)) if np.isfinite(r) else np.float32(np.inf)


def _as_points(array, name: str) -> np.ndarray:
    """``array`` as contiguous (N, 3) float32, finite (ValueError otherwise)."""
    return finite_rows(name, array, 3, np.float32)


def morton_codes(points: np.ndarray) -> np.ndarray:
    """(N,) uint32 Morton codes of (N, 3) ``points``, 10 bits an axis over their box."""
    # axis by axis (numpy reduces short rows slowly: 1 ms against 0.05 for 50k points)
    lo = np.array([points[:, a].min() for a in range(3)])
    scale = 1023.0 / np.maximum(np.array([points[:, a].max() for a in range(3)]) - lo, 1e-30)
    cells = ((points - lo) * scale).astype(np.uint32)

    def spread(v):
        v = (v | (v << 16)) & 0x030000FF
        v = (v | (v << 8)) & 0x0300F00F
        v = (v | (v << 4)) & 0x030C30C3
        return (v | (v << 2)) & 0x09249249

    return spread(cells[:, 0]) | (spread(cells[:, 1]) << 1) | (spread(cells[:, 2]) << 2)


def _spatial_order(points: np.ndarray) -> np.ndarray:
    """A permutation visiting ``points`` along a Morton curve, so that
    neighbouring work items search neighbouring parts of the tree (each
    query's answer is its own: the order of equal codes does not matter,
    and numpy's default sort takes 0.6 ms for 50k codes where its stable
    one takes 2.8)."""
    return np.argsort(morton_codes(points))


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
            photons = tuple(float4_rows(_as_points(a, name)) for a, name in ((power, "power"), (directions, "directions"), (normals, "normals")))
            if any(len(a) != len(pts) for a in photons):
                raise ValueError("photon attributes must have one row per point")
        on_device = points_on_device(device, pts)
        if photons is not None:
            photons = tuple(device.array_from(a) for a in photons)
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
        timer = StageTimer()
        with timer.stage("build"):
            built = build(device, points, photons, params)
        return cls(device, built, len(points), timer.ms["build"])

    # -- device arguments -------------------------------------------------

    def kernel_args(self) -> list:
        """Arguments matching POINT_TREE_PARAMS in accel/point_tree.h, in order."""
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
        return self.device.get(self._built.nodes)

    def node_info(self) -> np.ndarray:
        """PointNode payloads in preorder (POINT_NODE_DTYPE)."""
        return self.device.get(self._built.info)

    def positions(self) -> np.ndarray:
        """(N, 3) float32 point positions in leaf order."""
        return self.device.get(self._built.points)[: self.point_count, :3].copy()

    def photons(self) -> dict[str, np.ndarray]:
        """Photon attributes in leaf order: "power", "direction", "normal", each (N, 3)."""
        if not self.has_photons:
            raise ValueError("this tree was built without photon attributes")
        b, n = self._built, self.point_count
        return {name: self.device.get(a)[:n, :3].copy()
                for name, a in (("power", b.power), ("direction", b.direction), ("normal", b.normal))}

    def leaf_order(self) -> np.ndarray:
        """Original index of the point at each place of the leaf order."""
        return self.device.get(self._built.points)[: self.point_count, 3].copy().view(np.int32)

    # -- queries ------------------------------------------------------------

    def _kernel(self, name: str, k: int):
        return self.device.kernel(_PROGRAM, name, query_defines(k))

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
        kernel = self._kernel("PointTree_knn_batch", k)
        max_d2 = search_d2(max_radius)
        # batches of whole rows that fit one device allocation
        rows = max(1, min(m, dev.max_alloc_bytes // (8 * k), _ROWS_PER_LAUNCH))
        out_i = dev.empty(min(rows, m) * k * 4)
        out_d = dev.empty(min(rows, m) * k * 4)
        for s in range(0, m, rows):
            n = min(rows, m - s)
            part = q3[s : s + n]
            kernel(n, *self.kernel_args(), dev.to_device(float4_rows(part)),
                   dev.to_device(_spatial_order(part).astype(np.int32)), max_d2, np.int32(k), np.int32(n), out_i, out_d)
            dev.to_host(out_i, idx[s : s + n])
            dev.to_host(out_d, d2[s : s + n])
        return idx, d2

    def irradiance(self, positions: np.ndarray, normals: np.ndarray, k: int, max_radius: float | None = None,
                   filter: str = DENSITY_FILTER, normal_cos: float = DENSITY_NORMAL_COS, albedo: np.ndarray | None = None) -> np.ndarray:
        """Irradiance (M, 3) in W/m^2 at surface points with unit ``normals``,
        from the ``k`` nearest photons (within ``max_radius``) and a
        ``filter`` ("box", "cone" or "epanechnikov"). Photons from behind the
        surface, or stored where the normal differs by more than
        acos(normal_cos), are left out. With ``albedo`` (M, 3): the outgoing
        radiance of Lambertian surfaces, albedo / pi times that."""
        k = self._check_k(k)
        if filter not in FILTERS:
            raise ValueError(f"filter must be one of {sorted(FILTERS)}, not {filter!r}")
        photon_args = self.photon_args()
        pos = float4_rows(_as_points(positions, "positions"))
        nrm = float4_rows(_as_points(normals, "normals"))
        if len(nrm) != len(pos):
            raise ValueError("one normal per position")
        alb = float4_rows(_as_points(albedo, "albedo")) if albedo is not None else np.zeros((1, 4), np.float32)
        if albedo is not None and len(alb) != len(pos):
            raise ValueError("one albedo per position")
        m = len(pos)
        out = np.zeros((m, 4), np.float32)
        if m == 0:
            return out[:, :3]
        dev = self.device
        buf = dev.empty(out.nbytes)
        order = _spatial_order(pos[:, :3]).astype(np.int32)
        self._kernel("PointTree_density_batch", k)(
            m, *self.kernel_args(), *photon_args, dev.to_device(pos), dev.to_device(nrm), dev.to_device(alb),
            dev.to_device(order), search_d2(max_radius), np.int32(k), np.int32(FILTERS[filter]), np.float32(normal_cos),
            np.int32(albedo is not None), np.int32(m), buf)
        dev.to_host(buf, out)
        return out[:, :3]

    def radiance(self, positions: np.ndarray, normals: np.ndarray, albedo: np.ndarray, k: int, **options) -> np.ndarray:
        """Outgoing radiance (M, 3) of Lambertian surfaces with ``albedo``
        (M, 3): albedo / pi times the irradiance estimate."""
        return self.irradiance(positions, normals, k, albedo=albedo, **options)

    def irradiance_on_device(self, positions: cl.Buffer, normals: cl.Buffer, n: int, k: int, out: cl.Buffer,
                             filter: str = DENSITY_FILTER, normal_cos: float = DENSITY_NORMAL_COS,
                             max_radius: float | None = None) -> None:
        """Irradiance (float4 rows into ``out``) at ``n`` surface points
        whose float4 positions and unit normals are on the device, in their
        own order (points from a camera grid are coherent already), from the
        ``k`` nearest photons within ``max_radius``."""
        k = self._check_k(k)
        self._kernel("PointTree_density_batch", k)(
            n, *self.kernel_args(), *self.photon_args(), positions, normals, None, None, search_d2(max_radius),
            np.int32(k), np.int32(FILTERS[filter]), np.float32(normal_cos), np.int32(0), np.int32(n), out)


__all__ = ["PointTree", "FILTERS", "KDNODE_DTYPE", "POINT_NODE_DTYPE"]
