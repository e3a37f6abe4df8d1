"""Albedo tables of the GGX microfacet lobes (shading/microfacet.h), as
Cycles keeps them for its Multiscatter GGX:

  E[r, mu]     directional albedo of single-scattering GGX reflection with
               Fresnel 1, roughness r (alpha = r^2), mu = cos of the view
               angle: 1 - E is the energy multiple scattering would add;
  E_avg[r]     its cosine-weighted average over the hemisphere;
  S[z, mu, r]  the dielectric Fresnel remap s = (F(h) - F0) / (1 - F0)
               averaged over that lobe and divided by E, at the index
               eta = (1 + z^2) / (1 - z^2) (z = sqrt((eta - 1)/(eta + 1))):
               a dielectric layer of tinted F0 f reflects
               E (f + (1 - f) S) of the light;
  G[side, z, mu, r]   directional albedo of single-scattering GGX glass
               (reflection and refraction, Fresnel weighted), side 0 seen
               from outside (index eta > 1 beyond the surface), side 1 from
               inside (1 / eta), z as for S: 1 - G is what multiple
               scattering between the microfacets gives back;
  G_avg[side, z, r]   its cosine-weighted average over the hemisphere.

The tables are computed once by ``python -m gpu_core.shading.microfacet_tables``
(stratified VNDF samples, about a minute) and kept in ``microfacet_tables.npz``;
programs read them as the generated header ``shading/microfacet_tables.h``
(grid points i / (N - 1) on every axis, read bilinearly or trilinearly).
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

E_SIZE = 32  # roughness x mu points of E, roughness points of E_avg
S_SIZE = 16  # z x mu x roughness points of S
G_SIZE = 16  # z x mu x roughness points of G on each side, z x roughness of G_avg
_FILE = Path(__file__).with_name("microfacet_tables.npz")


def _vndf(wo: np.ndarray, alpha: float, u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """GGX visible normals for the view wo (Heitz 2018), (N, 3)."""
    vh = np.array([alpha * wo[0], alpha * wo[1], wo[2]])
    vh /= np.linalg.norm(vh)
    lensq = vh[0] ** 2 + vh[1] ** 2
    t1 = np.array([-vh[1], vh[0], 0.0]) / np.sqrt(lensq) if lensq > 0 else np.array([1.0, 0.0, 0.0])
    t2 = np.cross(vh, t1)
    r, phi = np.sqrt(u1), 2.0 * np.pi * u2
    a, b = r * np.cos(phi), r * np.sin(phi)
    s = 0.5 * (1.0 + vh[2])
    b = (1.0 - s) * np.sqrt(np.maximum(0.0, 1.0 - a * a)) + s * b
    nh = a[:, None] * t1 + b[:, None] * t2 + np.sqrt(np.maximum(0.0, 1.0 - a * a - b * b))[:, None] * vh
    ne = np.stack([alpha * nh[:, 0], alpha * nh[:, 1], np.maximum(nh[:, 2], 0.0)], axis=1)
    return ne / np.maximum(np.linalg.norm(ne, axis=1, keepdims=True), 1e-30)


def _lambda(cos: np.ndarray, alpha: float) -> np.ndarray:
    c2 = np.maximum(cos * cos, 1e-30)
    return 0.5 * (np.sqrt(1.0 + alpha * alpha * np.maximum(1.0 / c2 - 1.0, 0.0)) - 1.0)


def fresnel_dielectric(cos: np.ndarray, eta: float) -> np.ndarray:
    """Unpolarised Fresnel reflectance for the relative index eta (1 on
    total internal reflection), as Cycles' fresnel_dielectric_cos."""
    c = np.abs(cos)
    g = eta * eta - 1.0 + c * c
    out = np.ones_like(c)
    ok = g > 0.0
    g = np.sqrt(np.where(ok, g, 0.0))
    a = (g - c) / np.maximum(g + c, 1e-30)
    b = (c * (g + c) - 1.0) / np.maximum(c * (g - c) + 1.0, 1e-30)
    return np.where(ok, 0.5 * a * a * (1.0 + b * b), out)


def f0_from_ior(eta):
    return ((eta - 1.0) / (eta + 1.0)) ** 2


def ior_from_f0(f0):
    s = np.sqrt(np.clip(f0, 0.0, 0.999999))
    return (1.0 + s) / (1.0 - s)


def fresnel_average(eta: float, n: int = 4096) -> float:
    """Cosine-weighted hemispherical average of the dielectric Fresnel
    reflectance, 2 int F(mu) mu dmu (Cycles' fresnel_dielectric_Fss)."""
    mu = (np.arange(n) + 0.5) / n
    return float(2.0 * np.mean(fresnel_dielectric(mu, eta) * mu))


def _visible_normals(rough: float, mu: float, strata: int) -> tuple:
    """(mu, alpha, wo, h, wo . h) of strata^2 stratified visible normals
    for the view at cos mu (kept off grazing) and roughness rough."""
    mu = max(mu, 1e-4)
    alpha = max(rough * rough, 1e-6)
    wo = np.array([np.sqrt(max(0.0, 1.0 - mu * mu)), 0.0, mu])
    g = (np.arange(strata) + 0.5) / strata
    u1, u2 = (x.ravel() for x in np.meshgrid(g, g))
    h = _vndf(wo, alpha, u1, u2)
    return mu, alpha, wo, h, h @ wo


def _lobe(rough: float, mu: float, strata: int, eta: float | None = None) -> tuple[float, float]:
    """(E, S) of one grid point: the F = 1 albedo and the Fresnel remap's
    share of it (S = 0 without eta)."""
    mu, alpha, wo, h, cos_oh = _visible_normals(rough, mu, strata)
    wi = 2.0 * cos_oh[:, None] * h - wo
    valid = wi[:, 2] > 0.0
    weight = np.where(valid, (1.0 + _lambda(mu, alpha)) / (1.0 + _lambda(mu, alpha) + _lambda(wi[:, 2], alpha)), 0.0)
    e = float(weight.mean())
    if eta is None:
        return e, 0.0
    f0 = f0_from_ior(eta)
    s = np.clip((fresnel_dielectric(cos_oh, eta) - f0) / max(1.0 - f0, 1e-12), 0.0, 1.0)
    return e, float((weight * s).mean()) / max(e, 1e-12)


def _refract(wo: np.ndarray, h: np.ndarray, cos_oh: np.ndarray, eta: float) -> tuple[np.ndarray, np.ndarray]:
    """The refraction of wo by the microfacet normals h (eta = n_t / n_i)
    and where it exists (no total internal reflection)."""
    g = 1.0 - (1.0 - cos_oh * cos_oh) / (eta * eta)
    ok = g > 0.0
    wi = (cos_oh / eta - np.sqrt(np.where(ok, g, 0.0)))[:, None] * h - wo[None, :] / eta
    return wi / np.maximum(np.linalg.norm(wi, axis=1, keepdims=True), 1e-30), ok


def _glass(rough: float, mu: float, eta: float, strata: int) -> float:
    """G at one grid point: reflection with weight F, refraction with 1 - F,
    each sampled by the visible normals (weight G2 / G1)."""
    mu, alpha, wo, h, cos_oh = _visible_normals(rough, mu, strata)
    lo = _lambda(mu, alpha)
    fresnel = fresnel_dielectric(cos_oh, eta)
    wr = 2.0 * cos_oh[:, None] * h - wo
    reflect = np.where(wr[:, 2] > 0.0, (1.0 + lo) / (1.0 + lo + _lambda(wr[:, 2], alpha)), 0.0)
    wt, ok = _refract(wo, h, cos_oh, eta)
    refract = np.where(ok & (wt[:, 2] < 0.0), (1.0 + lo) / (1.0 + lo + _lambda(wt[:, 2], alpha)), 0.0)
    if abs(eta - 1.0) < 1e-4:
        refract = np.ones_like(refract)  # at index 1 the light goes straight through, as the kernels have it
    return float((fresnel * reflect + (1.0 - fresnel) * refract).mean())


def _cosine_average(grid: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """2 int E(mu) mu dmu of each row of E over the mu grid (last axis)."""
    mu_fine = (np.arange(256) + 0.5) / 256
    flat = rows.reshape(-1, rows.shape[-1])
    return np.array([2.0 * np.mean(np.interp(mu_fine, grid, row) * mu_fine) for row in flat]).reshape(rows.shape[:-1])


def eta_of_z(z: float) -> float:
    z2 = min(z * z, 1.0 - 1e-6)
    return (1.0 + z2) / (1.0 - z2)


def compute_glass(strata: int = 96) -> dict[str, np.ndarray]:
    """G and G_avg (strata^2 samples a point); z = 0 is index 1, where
    glass lets everything through."""
    grid = np.linspace(0.0, 1.0, G_SIZE)
    g = np.array([[[[_glass(r, mu, eta_of_z(z) ** (1 - 2 * side), strata) for mu in grid] for r in grid]
                   for z in grid] for side in (0, 1)])  # [side, z, r, mu]
    g_avg = _cosine_average(grid, g)
    return {"G": np.swapaxes(g, 2, 3).astype(np.float32), "G_avg": g_avg.astype(np.float32)}


def compute(strata_e: int = 256, strata_s: int = 96) -> dict[str, np.ndarray]:
    """The tables, by stratified VNDF sampling (strata^2 samples a point)."""
    grid_e = np.linspace(0.0, 1.0, E_SIZE)
    e = np.array([[_lobe(r, mu, strata_e)[0] for mu in grid_e] for r in grid_e])
    grid_s = np.linspace(0.0, 1.0, S_SIZE)
    s = np.array([[[_lobe(r, mu, strata_s, eta_of_z(z))[1] for r in grid_s] for mu in grid_s] for z in grid_s])
    return {"E": e.astype(np.float32), "E_avg": _cosine_average(grid_e, e).astype(np.float32), "S": s.astype(np.float32),
            **compute_glass()}


@functools.cache
def tables() -> dict[str, np.ndarray]:
    with np.load(_FILE) as data:
        return {key: data[key] for key in data.files}


def _c_array(name: str, values: np.ndarray) -> str:
    body = ",".join(f"{v:.7e}f" for v in values.ravel())
    return f"__constant float {name}[{values.size}] = {{{body}}};"


def header() -> str:
    """The generated ``shading/microfacet_tables.h``."""
    t = tables()
    return ("/* Generated from gpu_core/shading/microfacet_tables.npz (microfacet_tables.py). */\n"
            "#ifndef GPUGI_MICROFACET_TABLES_H\n#define GPUGI_MICROFACET_TABLES_H\n"
            f"#define MICROFACET_E_SIZE {E_SIZE}\n#define MICROFACET_S_SIZE {S_SIZE}\n#define MICROFACET_G_SIZE {G_SIZE}\n"
            f"{_c_array('Microfacet_table_E', t['E'])}\n{_c_array('Microfacet_table_E_avg', t['E_avg'])}\n"
            f"{_c_array('Microfacet_table_S', t['S'])}\n{_c_array('Microfacet_table_G', t['G'])}\n"
            f"{_c_array('Microfacet_table_G_avg', t['G_avg'])}\n#endif\n")


if __name__ == "__main__":
    np.savez_compressed(_FILE, **compute())
    print(f"wrote {_FILE}")
