"""Shading points of small analytic scenes seen by a pinhole camera, for the
irradiance-cache tests: a plane, two perpendicular planes, a sphere and the
inside of a box. Each pixel whose ray hits something gives one point."""

from __future__ import annotations

import numpy as np


def _camera_rays(width: int, height: int, eye, target, fov: float = 0.9):
    eye, target = np.asarray(eye, np.float64), np.asarray(target, np.float64)
    forward = target - eye
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    if np.linalg.norm(right) < 1e-9:
        right = np.cross(forward, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    xs, ys = np.meshgrid(np.arange(width), np.arange(height))
    half = np.tan(fov / 2.0)
    u = ((xs + 0.5) / width * 2.0 - 1.0) * half * width / max(width, height)
    v = ((ys + 0.5) / height * 2.0 - 1.0) * half * height / max(width, height)
    dirs = forward + u[..., None] * right + v[..., None] * up
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    pixels = np.stack([xs, ys], axis=-1).reshape(-1, 2)
    return eye, dirs.reshape(-1, 3), pixels


def _rect(axis: int, at: float, lo, hi, normal_sign: float):
    """Axis-aligned rectangle: coordinate ``axis`` = ``at``, the others within lo..hi."""
    return ("rect", axis, at, np.asarray(lo, float), np.asarray(hi, float), normal_sign)


def _hit(eye, dirs, prims):
    n = len(dirs)
    best_t = np.full(n, np.inf)
    best_n = np.zeros((n, 3))
    for prim in prims:
        if prim[0] == "rect":
            _, axis, at, lo, hi, sign = prim
            with np.errstate(divide="ignore", invalid="ignore"):
                t = (at - eye[axis]) / dirs[:, axis]
            p = eye + t[:, None] * dirs
            others = [a for a in range(3) if a != axis]
            inside = (t > 1e-9) & np.all((p[:, others] >= lo) & (p[:, others] <= hi), axis=1)
            normal = np.zeros(3)
            normal[axis] = sign
            take = inside & (t < best_t)
            best_t[take] = t[take]
            best_n[take] = normal
        else:
            _, centre, radius = prim
            oc = eye - centre
            b = dirs @ oc
            disc = b * b - (oc @ oc - radius * radius)
            t = -b - np.sqrt(np.maximum(disc, 0.0))
            take = (disc > 0) & (t > 1e-9) & (t < best_t)
            best_t[take] = t[take]
            best_n[take] = (eye + t[take, None] * dirs[take] - centre) / radius
    hit = np.isfinite(best_t)
    pos = eye + best_t[hit, None] * dirs[hit]
    return pos, best_n[hit], hit


SHAPES = {
    "plane": dict(eye=(0.0, -2.5, 1.6), target=(0.0, 0.0, 0.0),
                  prims=[_rect(2, 0.0, (-3, -3), (3, 3), 1.0)]),
    "two_planes": dict(eye=(1.6, -2.2, 1.4), target=(0.0, 0.0, 0.3),
                       prims=[_rect(2, 0.0, (-1, -1), (1, 1), 1.0), _rect(0, -1.0, (-1, 0), (1, 2), 1.0)]),
    "sphere": dict(eye=(0.0, -3.0, 0.5), target=(0.0, 0.0, 0.0), prims=[("sphere", np.zeros(3), 0.8)]),
    "box": dict(eye=(0.0, -2.9, 1.0), target=(0.0, 0.0, 1.0),
                prims=[_rect(2, 0.0, (-1, -1), (1, 1), 1.0), _rect(2, 2.0, (-1, -1), (1, 1), -1.0),
                       _rect(0, -1.0, (-1, 0), (1, 2), 1.0), _rect(0, 1.0, (-1, 0), (1, 2), -1.0),
                       _rect(1, 1.0, (-1, 0), (1, 2), -1.0), ("sphere", np.array([0.3, 0.2, 0.5]), 0.5)]),
}


def shading_points(shape: str, width: int, height: int, scale: float = 1.0, offset=(0.0, 0.0, 0.0)):
    """positions (N, 3) float32, unit normals (N, 3) float32, pixels (N, 2) int32."""
    spec = SHAPES[shape]
    eye, dirs, pixels = _camera_rays(width, height, spec["eye"], spec["target"])
    pos, nrm, hit = _hit(eye, dirs, spec["prims"])
    pos = pos * scale + np.asarray(offset, np.float64)
    return pos.astype(np.float32), nrm.astype(np.float32), pixels[hit].astype(np.int32)
