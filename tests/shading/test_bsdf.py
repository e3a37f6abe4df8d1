"""The BSDF kernels (shading/bsdf.h, microfacet.h) probed on the device
through shading/bsdf_check.cl: each sampling routine against its pdf (a
chi-square test over the sphere), energy (white furnace), reciprocity, and
the extremes of roughness and index."""

from types import SimpleNamespace

import numpy as np
import pytest
from scenes_py import camera_looking_down, make_scene, quad
from scipy.interpolate import RegularGridInterpolator
from scipy.stats import chi2

from gpu_core.device.layout import MATERIAL_DTYPE
from gpu_core.scene import MATERIAL_GLASS, MATERIAL_GLOSSY, Lights, Materials
from gpu_core.scene.tables import material_table
from gpu_core.shading import microfacet_tables

PROGRAM = "shading/bsdf_check.cl"
SAMPLE_ALL = 3
LABEL_DIFFUSE = 1
LABEL_SINGULAR = 4


def material(**row) -> np.ndarray:
    """The device row of a material given as Materials.make takes it."""
    return material_table(SimpleNamespace(materials=Materials.make([row]), textures=[]))


def view(cos_theta: float) -> np.ndarray:
    return np.array([np.sqrt(1 - cos_theta**2), 0.0, cos_theta, 0.0], np.float32)


UP = np.array([0.0, 0.0, 1.0, 0.0], np.float32)


def sample(device, row, wo, n, entering=True, seed=1, ns=UP, u=None):
    """n sampled directions (N, 3), labels, weights (N, 3), pdfs, on a
    surface of geometric normal +z and shading normal ``ns``: from the
    random stream of ``seed``, or from the given numbers ``u`` ((n, 4):
    lobe, u1, u2, u3)."""
    out_dir, out_weight = device.empty(16 * n), device.empty(16 * n)
    head = (device.to_device(row), wo, ns, np.int32(entering), np.int32(SAMPLE_ALL))
    if u is None:
        device.kernel(PROGRAM, "BsdfCheck_sample")(n, *head, np.uint32(seed), np.int32(n), out_dir, out_weight)
    else:
        device.kernel(PROGRAM, "BsdfCheck_sample_at")(n, *head, device.to_device(np.asarray(u, np.float32)),
                                                      np.int32(n), out_dir, out_weight)
    d = device.read(out_dir, (n, 4), np.float32)
    w = device.read(out_weight, (n, 4), np.float32)
    return d[:, :3].astype(np.float64), d[:, 3].astype(int), w[:, :3].astype(np.float64), w[:, 3].astype(np.float64)


def evaluate(device, row, wo, wi, entering=True, ns=UP, parts=False):
    """f cos (diffuse + glossy, (N, 3)) and pdf at directions wi; with
    ``parts`` the diffuse and glossy parts apart."""
    n = len(wi)
    dirs = np.zeros((n, 4), np.float32)
    dirs[:, :3] = wi
    out_d, out_g = device.empty(16 * n), device.empty(16 * n)
    device.kernel(PROGRAM, "BsdfCheck_eval")(n, device.to_device(row), wo, ns, np.int32(entering),
                                             np.int32(SAMPLE_ALL), device.to_device(dirs), np.int32(n), out_d, out_g)
    d = device.read(out_d, (n, 4), np.float32).astype(np.float64)
    g = device.read(out_g, (n, 4), np.float32).astype(np.float64)
    if parts:
        return d[:, :3], g[:, :3], g[:, 3]
    return d[:, :3] + g[:, :3], g[:, 3]


# -- sampling against the pdf ---------------------------------------------------

# bins in cos(theta) over [-1, 1] and phi; sub-points per bin side. The
# midpoint rule resolves lobes down to roughness 0.2 this way; sharper ones
# are checked by the weight test (f / pdf) and the furnace tests
THETA_BINS, PHI_BINS, SUB = 24, 24, 24


def glossy_normal(wo, n) -> np.ndarray:
    """The glossy lobes' normal over the geometric normal +z for the view wo
    and shading normal n: bsdf.h's Bsdf_glossy_normal (Cycles'
    ensure_valid_specular_reflection), in numpy."""
    wo, n, z = np.asarray(wo[:3], np.float64), np.asarray(n[:3], np.float64), np.array([0.0, 0.0, 1.0])
    iz = wo[2]
    threshold = min(0.9 * iz, 0.01)
    if (2 * (n @ wo) * n - wo)[2] >= threshold:
        return n
    x = n - n[2] * z
    x = x / np.linalg.norm(x) if np.linalg.norm(x) > 1e-7 else n
    ix = wo @ x
    a = ix * ix + iz * iz
    b, c = 2 * (a + iz * threshold), (threshold + iz) ** 2
    root = np.sqrt(max(b * b - 4 * a * c, 0.0))
    nz2 = np.clip(0.25 * (b + root if ix < 0 else b - root) / a, 0.0, 1.0)
    g = np.sqrt(1 - nz2) * x + np.sqrt(nz2) * z
    return g / np.linalg.norm(g)


def refracted_by_a_microfacet(row, wo, wi, entering=True, ns=UP) -> np.ndarray:
    """For each wi, whether a microfacet could have scattered wo there: any
    direction above the surface, and below it those whose half vector of
    refraction (turned to the glossy lobes' side) faces wo and not wi.
    Cycles' evaluation, and GPU GI's with it, gives the other directions
    below a value and a pdf too (the cosines to the half vector by their
    absolute values), though sampling never goes there."""
    ior = float(row["ior"][0])
    eta = ior if entering else 1.0 / ior
    h = -(eta * wi + wo[:3])
    h /= np.maximum(np.linalg.norm(h, axis=1, keepdims=True), 1e-12)
    h *= np.where(h @ glossy_normal(wo, ns) < 0, -1.0, 1.0)[:, None]
    return (wi[:, 2] >= 0) | ((h @ wo[:3] > 0) & ((h * wi).sum(axis=1) < 0))


def binned_pdf(device, row, wo, entering=True, ns=UP) -> np.ndarray:
    """The pdf of the directions sampling can reach, integrated over each
    (cos theta, phi) bin by the midpoint rule on SUB x SUB points a bin."""
    fine_c = (np.arange(THETA_BINS * SUB) + 0.5) / (THETA_BINS * SUB) * 2 - 1
    fine_p = (np.arange(PHI_BINS * SUB) + 0.5) / (PHI_BINS * SUB) * 2 * np.pi
    c, p = np.meshgrid(fine_c, fine_p, indexing="ij")
    s = np.sqrt(1 - c**2)
    wi = np.stack([s * np.cos(p), s * np.sin(p), c], -1).reshape(-1, 3)
    _, pdf = evaluate(device, row, wo, wi, entering, ns)
    pdf = np.where(refracted_by_a_microfacet(row, wo, wi, entering, ns), pdf, 0.0)
    cell = (2.0 / (THETA_BINS * SUB)) * (2 * np.pi / (PHI_BINS * SUB))  # d(cos) d(phi) = solid angle
    return (pdf.reshape(THETA_BINS, SUB, PHI_BINS, SUB) * cell).sum(axis=(1, 3))


def chi_square_p(device, row, wo, entering=True, n=400_000, ns=UP) -> float:
    """p-value of the sampled directions' histogram against the pdf (lost
    samples are a bin of their own; bins expecting fewer than 5 merged)."""
    wi, label, _, _ = sample(device, row, wo, n, entering, ns=ns)
    assert not (label & LABEL_SINGULAR).any()
    ok = label != 0
    c = np.clip(wi[ok, 2], -1, 1)
    phi = np.mod(np.arctan2(wi[ok, 1], wi[ok, 0]), 2 * np.pi)
    ti = np.minimum(((c + 1) / 2 * THETA_BINS).astype(int), THETA_BINS - 1)
    pi = np.minimum((phi / (2 * np.pi) * PHI_BINS).astype(int), PHI_BINS - 1)
    observed = np.bincount(ti * PHI_BINS + pi, minlength=THETA_BINS * PHI_BINS).astype(np.float64)
    expected = binned_pdf(device, row, wo, entering, ns).ravel() * n
    observed = np.append(observed, n - ok.sum())
    expected = np.append(expected, max(n - expected.sum(), 0.0))
    order = np.argsort(expected)
    obs, exp = observed[order], expected[order]
    small = np.cumsum(exp) < 5 * 4  # merge the smallest bins into one
    obs = np.append(obs[~small], obs[small].sum())
    exp = np.append(exp[~small], exp[small].sum())
    keep = exp > 0
    stat = ((obs[keep] - exp[keep]) ** 2 / exp[keep]).sum()
    return float(chi2.sf(stat, keep.sum() - 1))


CASES = {
    "metal_rough_0.3": dict(base_color=(0.9, 0.6, 0.3), metallic=1.0, roughness=0.3),
    "metal_rough_1": dict(base_color=(0.9, 0.9, 0.9), metallic=1.0, roughness=1.0),
    "plastic_layered_0.5": dict(base_color=(0.5, 0.2, 0.1), roughness=0.5, specular_ior_level=0.5),
    "rough_diffuse_0.8": dict(base_color=(0.7, 0.5, 0.3), roughness=0.5, specular_ior_level=0.5,
                              diffuse_roughness=0.8),
    "plastic_layered_0.2": dict(base_color=(0.8, 0.8, 0.8), roughness=0.2, specular_ior_level=1.0),
    "glass_rough_0.3": dict(base_color=(1, 1, 1), transmission=1.0, roughness=0.3, ior=1.5),
    "glass_rough_0.7_tinted": dict(base_color=(0.6, 0.8, 1.0), transmission=1.0, roughness=0.7, ior=1.33),
    "glossy_node_0.2": dict(base_color=(0.7, 0.7, 0.7), roughness=0.2, shader=MATERIAL_GLOSSY),
    "principled_mix": dict(base_color=(0.6, 0.5, 0.4), metallic=0.4, transmission=0.5, roughness=0.4,
                           specular_ior_level=0.5),
}


@pytest.mark.parametrize("case", CASES)
@pytest.mark.parametrize("cos_theta", [0.9, 0.3])
def test_sampled_directions_follow_the_pdf(device, case, cos_theta):
    p = chi_square_p(device, material(**CASES[case]), view(cos_theta))
    assert p > 1e-4, f"chi-square p = {p:.2e}"


def test_rough_glass_sampled_from_inside_follows_the_pdf(device):
    row = material(base_color=(1, 1, 1), transmission=1.0, roughness=0.4, ior=1.5)
    assert chi_square_p(device, row, view(0.8), entering=False) > 1e-4


def test_weights_are_the_bsdf_over_the_pdf(device):
    row = material(**CASES["principled_mix"])
    wo = view(0.6)
    wi, label, weight, pdf = sample(device, row, wo, 2000)
    ok = label != 0
    f, pdf_eval = evaluate(device, row, wo, wi[ok])
    np.testing.assert_allclose(pdf_eval, pdf[ok], rtol=2e-3)
    np.testing.assert_allclose(weight[ok] * pdf[ok, None], f, rtol=2e-3, atol=1e-7)


# -- energy -------------------------------------------------------------------------


def albedo(device, row, cos_theta, entering=True, n=200_000) -> np.ndarray:
    """Directional albedo: the mean sample weight (lost samples count 0)."""
    _, label, weight, _ = sample(device, row, view(cos_theta), n, entering)
    return np.where((label != 0)[:, None], weight, 0.0).mean(axis=0)


@pytest.mark.parametrize("roughness", [0.05, 0.3, 0.7, 1.0])
@pytest.mark.parametrize("cos_theta", [1.0, 0.5, 0.1])
def test_white_metal_keeps_all_the_energy(device, roughness, cos_theta):
    # Multiscatter GGX: the single-scattering lobe times 1 / E (1 + F_ms (1 - E) / E with F = 1)
    a = albedo(device, material(base_color=(1, 1, 1), metallic=1.0, roughness=roughness), cos_theta)
    np.testing.assert_allclose(a, 1.0, atol=0.015)


@pytest.mark.parametrize("roughness", [0.0, 0.3, 0.7, 1.0])
@pytest.mark.parametrize("level", [0.5, 1.0])
def test_white_plastic_reflects_at_most_all_the_light(device, roughness, level):
    # the specular layer takes its albedo from the diffuse base (Cycles' albedo
    # scaling): together about 1, never more
    for cos_theta in (1.0, 0.5, 0.1):
        a = albedo(device, material(base_color=(1, 1, 1), roughness=roughness, specular_ior_level=level), cos_theta)
        assert a.max() <= 1.01
        assert a.min() >= 0.9


@pytest.mark.parametrize("roughness", [0.0, 0.1, 0.5, 1.0])
@pytest.mark.parametrize("ior", [1.05, 1.5, 2.5])
def test_clear_glass_keeps_all_the_energy(device, roughness, ior):
    # Multiscatter GGX on glass: the single-scattering lobe over its albedo
    # (the G tables), from outside and from inside, down to grazing views
    for entering in (True, False):
        for cos_theta in (1.0, 0.5, 0.1):
            a = albedo(device, material(base_color=(1, 1, 1), transmission=1.0, roughness=roughness, ior=ior),
                       cos_theta, entering)
            np.testing.assert_allclose(a, 1.0, atol=0.03)


def ggx_albedo(alpha: float, cos_theta: float, steps: int = 1000) -> float:
    """Directional albedo of white single-scattering GGX (height-correlated
    Smith), by the midpoint rule over cos(theta) and phi."""
    c = (np.arange(steps) + 0.5) / steps
    phi = (np.arange(steps) + 0.5) / steps * 2 * np.pi
    c, phi = np.meshgrid(c, phi, indexing="ij")
    s = np.sqrt(1 - c**2)
    wi = np.stack([s * np.cos(phi), s * np.sin(phi), c], -1)
    wo = np.array([np.sqrt(1 - cos_theta**2), 0.0, cos_theta])
    h = wi + wo
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    a2 = alpha**2
    d = a2 / (np.pi * (1 + (a2 - 1) * h[..., 2] ** 2) ** 2)
    lam = lambda x: (np.sqrt(1 + a2 * (1 - x * x) / (x * x)) - 1) / 2  # noqa: E731
    g = 1 / (1 + lam(cos_theta) + lam(c))
    return float((d * g / (4 * cos_theta)).mean() * 2 * np.pi)


@pytest.mark.parametrize("roughness", [0.3, 0.7, 1.0])
@pytest.mark.parametrize("cos_theta", [1.0, 0.5])
def test_the_ggx_distribution_keeps_single_scattering_only(device, roughness, cos_theta):
    # Cycles' GGX (not Multiscatter GGX): a white metal reflects the single-scattering albedo
    single = albedo(device, material(base_color=(1, 1, 1), metallic=1.0, roughness=roughness, single_scatter=1),
                    cos_theta)
    np.testing.assert_allclose(single, ggx_albedo(roughness**2, cos_theta), atol=0.01)


def test_ggx_glass_loses_what_multiple_scattering_gives_back(device):
    def white(roughness, single):
        return material(base_color=(1, 1, 1), transmission=1.0, ior=1.5, roughness=roughness,
                        single_scatter=int(single))
    np.testing.assert_allclose(albedo(device, white(0.05, True), 1.0), 1.0, atol=0.02)
    assert (albedo(device, white(1.0, True), 0.5) < 0.95).all()
    np.testing.assert_allclose(albedo(device, white(1.0, False), 0.5), 1.0, atol=0.03)


def test_metal_colour_comes_through_multiple_scattering_saturated(device):
    # F_ms: light bouncing between coloured microfacets is tinted more than once
    rough = albedo(device, material(base_color=(0.9, 0.5, 0.2), metallic=1.0, roughness=1.0), 0.7)
    smooth = albedo(device, material(base_color=(0.9, 0.5, 0.2), metallic=1.0, roughness=0.05), 0.7)
    assert rough[2] / rough[0] < smooth[2] / smooth[0]
    assert rough[0] > 0.75


# -- a shading normal tilted away from the viewer -----------------------------------

# a smooth normal at a silhouette (or a normal map's) facing away from a view
# 72 degrees off the geometric normal
AWAY_NORMAL = np.array([-0.6, 0.0, 0.8, 0.0], np.float32)
GRAZING = view(0.3)


def test_a_shading_normal_facing_away_keeps_the_diffuse_lobe_on_it(device):
    assert float(AWAY_NORMAL[:3] @ GRAZING[:3]) < 0
    row = material(base_color=(0.8, 0.5, 0.2), specular_ior_level=0.0)
    diffuse, glossy, _ = evaluate(device, row, GRAZING, AWAY_NORMAL[None, :3], ns=AWAY_NORMAL, parts=True)
    # f cos along the shading normal is albedo / pi (cos 1 there, not 0.8 as to +z)
    np.testing.assert_allclose(diffuse[0], np.array([0.8, 0.5, 0.2]) / np.pi, rtol=1e-4)


@pytest.mark.parametrize("row", [dict(metallic=1.0, roughness=0.5), dict(roughness=0.5),
                                 dict(transmission=1.0, roughness=0.5)], ids=["metal", "plastic", "glass"])
def test_glossy_lobes_on_a_normal_facing_away_sample_their_raised_normal(device, row):
    # Cycles raises the glossy lobes' normal towards the geometric one just
    # enough that the view's mirror direction leaves the surface: sampling
    # and evaluation agree in that frame, reflections stay above the surface
    row = material(base_color=(0.8, 0.8, 0.8), **row)
    assert chi_square_p(device, row, GRAZING, ns=AWAY_NORMAL) > 1e-3
    wi, label, weight, pdf = sample(device, row, GRAZING, 20_000, ns=AWAY_NORMAL)
    reflected, transmitted = (label != 0) & ((label & 8) == 0), (label & 8) != 0
    assert (label != 0).mean() > 0.3
    assert (wi[reflected, 2] > 0).all() and (wi[transmitted, 2] < 0).all()
    assert np.isfinite(weight).all() and weight.max() <= 4.0
    ok = label != 0
    f, pdf_eval = evaluate(device, row, GRAZING, wi[ok], ns=AWAY_NORMAL)
    np.testing.assert_allclose(pdf_eval, pdf[ok], rtol=2e-3)
    np.testing.assert_allclose(weight[ok] * pdf[ok, None], f, rtol=2e-3, atol=1e-7)


# -- rough diffuse (Oren-Nayar) --------------------------------------------------------


@pytest.mark.parametrize("roughness", [0.5, 1.0])
def test_white_rough_diffuse_keeps_all_the_energy(device, roughness):
    # Fujii's Oren-Nayar with OpenPBR's multiple-scattering term, as Cycles
    for cos_theta in (1.0, 0.5, 0.1):
        a = albedo(device, material(base_color=(1, 1, 1), diffuse_roughness=roughness), cos_theta)
        np.testing.assert_allclose(a, 1.0, atol=0.01)


def test_rough_diffuse_scatters_back_toward_the_light(device):
    # a rough surface seen 60 degrees off is brighter lit from behind the
    # viewer than from the mirror direction; a Lambertian one is not
    wo = view(0.5)
    back, mirror = wo[:3].copy(), wo[:3] * np.array([-1.0, -1.0, 1.0])
    for roughness, brighter in ((0.0, False), (1.0, True)):
        f, _ = evaluate(device, material(base_color=(0.8, 0.8, 0.8), diffuse_roughness=roughness), wo,
                        np.stack([back, mirror]))
        ratio = f[0, 0] / f[1, 0]
        assert (ratio > 1.3) if brighter else ratio == pytest.approx(1.0, rel=1e-5)


# -- anisotropy ---------------------------------------------------------------------

ANISOTROPIC = {
    "principled_metal_0.8": dict(base_color=(0.9, 0.9, 0.9), metallic=1.0, roughness=0.5, anisotropy=0.8),
    "principled_plastic_0.8_turned": dict(base_color=(0.5, 0.5, 0.5), roughness=0.4, specular_ior_level=0.5,
                                          anisotropy=0.8, anisotropic_rotation=0.125),
    "glossy_node_-0.6": dict(base_color=(0.8, 0.8, 0.8), roughness=0.45, shader=MATERIAL_GLOSSY, anisotropy=-0.6),
}


@pytest.mark.parametrize("case", ANISOTROPIC)
@pytest.mark.parametrize("cos_theta", [1.0, 0.5])
def test_anisotropic_lobes_sample_their_pdf(device, case, cos_theta):
    row = material(**ANISOTROPIC[case])
    assert chi_square_p(device, row, view(cos_theta)) > 1e-3
    wi, label, weight, pdf = sample(device, row, view(cos_theta), 2000)
    ok = label != 0
    f, pdf_eval = evaluate(device, row, view(cos_theta), wi[ok])
    np.testing.assert_allclose(pdf_eval, pdf[ok], rtol=2e-3)
    np.testing.assert_allclose(weight[ok] * pdf[ok, None], f, rtol=2e-3, atol=1e-7)


def test_anisotropy_stretches_the_highlight_along_the_tangent(device):
    # the check surface's tangent is +x: Principled's Anisotropic widens the
    # lobe along it, the Glossy node's positive Anisotropy across it
    spread = {}
    for name, row in (("principled", dict(metallic=1.0, roughness=0.5, anisotropy=0.9)),
                      ("glossy", dict(roughness=0.5, shader=MATERIAL_GLOSSY, anisotropy=0.6)),
                      ("isotropic", dict(metallic=1.0, roughness=0.5))):
        wi, label, _, _ = sample(device, material(base_color=(1, 1, 1), **row), view(1.0), 50_000)
        spread[name] = np.std(wi[label != 0, 0]) / np.std(wi[label != 0, 1])
    assert spread["principled"] > 1.5 and spread["glossy"] < 1 / 1.5
    assert abs(spread["isotropic"] - 1.0) < 0.05


# albedo of white metal at roughness 0.6, views 1, 0.5, 0.2, measured: the
# albedo tables are read at sqrt(alpha_x alpha_y) = roughness^2, as Cycles
# reads them, so a stretched lobe gets the isotropic lobe's compensation:
# 0.96 / 1.00 / 1.03 at Anisotropic 0.5, 0.57 / 0.77 / 0.92 at 1
@pytest.mark.parametrize("anisotropy, least", [(0.5, 0.95), (1.0, 0.55)])
def test_white_anisotropic_metal_gets_the_isotropic_lobe_s_compensation(device, anisotropy, least):
    for cos_theta in (1.0, 0.5, 0.2):
        a = albedo(device, material(base_color=(1, 1, 1), metallic=1.0, roughness=0.6, anisotropy=anisotropy),
                   cos_theta)
        assert least <= a.min() and a.max() <= 1.04, (cos_theta, a)


# -- reciprocity and extremes --------------------------------------------------------


def test_glass_reflection_is_reciprocal(device):
    row = material(base_color=(1, 1, 1), transmission=1.0, roughness=0.4, ior=1.5)
    rng = np.random.default_rng(3)
    a, b = rng.normal(size=(2, 20, 3))
    a[:, 2], b[:, 2] = np.abs(a[:, 2]) + 0.1, np.abs(b[:, 2]) + 0.1  # both above the surface
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    f_ab = np.array([evaluate(device, row, np.append(x, 0).astype(np.float32), y[None])[0][0] / y[2]
                     for x, y in zip(a, b)])
    f_ba = np.array([evaluate(device, row, np.append(y, 0).astype(np.float32), x[None])[0][0] / x[2]
                     for x, y in zip(a, b)])
    # the single-scattering lobe is reciprocal; Multiscatter GGX scales it by
    # 1 / G of the view (as Cycles does), which is not
    grid = np.linspace(0, 1, microfacet_tables.G_SIZE)
    g = RegularGridInterpolator((grid, grid, grid), microfacet_tables.tables()["G"][0].astype(np.float64))
    z = np.sqrt((1.5 - 1) / (1.5 + 1))
    g_a, g_b = (g(np.stack([np.full(20, z), v[:, 2], np.full(20, 0.4)], -1)) for v in (a, b))
    np.testing.assert_allclose(f_ab * g_a[:, None], f_ba * g_b[:, None], rtol=1e-3, atol=1e-6)
    assert np.abs(f_ab / f_ba - 1).max() > 1e-3  # the scaling shows


@pytest.mark.parametrize("roughness", [0.0, 1e-4, 1e-3, 0.5, 1.0])
@pytest.mark.parametrize("ior", [1.0, 1.0001, 3.0])
@pytest.mark.parametrize("cos_theta", [1.0, 1e-3])
def test_extremes_give_finite_bounded_samples(device, roughness, ior, cos_theta):
    for row in (material(base_color=(1, 1, 1), transmission=1.0, roughness=roughness, ior=ior),
                material(base_color=(1, 1, 1), metallic=1.0, roughness=roughness),
                material(base_color=(1, 1, 1), roughness=roughness, specular_ior_level=1.0, ior=ior)):
        for entering in (True, False):
            wi, label, weight, pdf = sample(device, row, view(cos_theta), 20_000, entering)
            assert np.isfinite(weight).all() and np.isfinite(pdf).all() and np.isfinite(wi).all()
            assert (weight >= 0).all()
            # no firefly explosion: one sample weighs at most a few times the light it carries
            assert weight.max() <= 4.0
            assert np.abs(np.linalg.norm(wi[label != 0], axis=1) - 1).max() < 1e-3


def test_diffuse_samples_at_the_disk_rim_leave_above_the_surface(device):
    # u1 the largest numbers the random streams give (1 - k / 2^24), the
    # angle all round: the sampled height must not cancel to 0 (a direction
    # in the plane, lost), nor the sampled angle's cosine and sine stretch it
    # (Intel's CPU runtime's native pair errs by 1.5e-4: both happened)
    u1 = 1.0 - np.arange(1, 17) / 2.0**24
    u2 = (np.arange(4096) + 0.5) / 4096
    u = np.zeros((len(u1) * len(u2), 4), np.float32)
    u[:, 1], u[:, 2] = np.repeat(u1, len(u2)), np.tile(u2, len(u1))
    wi, label, weight, pdf = sample(device, material(base_color=(0.8, 0.8, 0.8)), view(0.6), len(u), u=u)
    assert (label == LABEL_DIFFUSE).all()
    assert (wi[:, 2] > 0).all() and (pdf > 0).all()
    np.testing.assert_allclose(np.linalg.norm(wi, axis=1), 1.0, atol=1e-5)
    np.testing.assert_allclose(weight, 0.8, rtol=1e-4)


def test_roughness_below_the_singular_bound_is_a_perfect_mirror(device):
    for roughness in (0.0, 1e-4, 0.003):
        wi, label, weight, _ = sample(device, material(base_color=(0.9, 0.6, 0.3), metallic=1.0, roughness=roughness),
                                      view(0.8), 1000)
        assert (label & LABEL_SINGULAR).all()
        np.testing.assert_allclose(wi, np.tile([-0.6, 0.0, 0.8], (1000, 1)), atol=1e-5)


def test_tables_match_a_fresh_computation(device):
    # the stored albedo tables against a quick recomputation at a few points
    t = microfacet_tables.tables()
    grid = np.linspace(0, 1, microfacet_tables.E_SIZE)
    for i, j in ((5, 3), (16, 16), (31, 1), (31, 31)):
        e, _ = microfacet_tables._lobe(grid[i], grid[j], 128)
        assert abs(t["E"][i, j] - e) < 2e-3
    grid_s = np.linspace(0, 1, microfacet_tables.S_SIZE)
    for z, m, r in ((4, 8, 8), (10, 15, 3), (2, 2, 15)):
        _, s = microfacet_tables._lobe(grid_s[r], grid_s[m], 64, microfacet_tables.eta_of_z(grid_s[z]))
        assert abs(t["S"][z, m, r] - s) < 3e-3
    grid_g = np.linspace(0, 1, microfacet_tables.G_SIZE)
    for side, z, m, r in ((0, 7, 15, 8), (1, 7, 10, 12), (0, 3, 2, 15), (1, 12, 15, 15)):
        eta = microfacet_tables.eta_of_z(grid_g[z]) ** (1 - 2 * side)
        assert abs(t["G"][side, z, m, r] - microfacet_tables._glass(grid_g[r], grid_g[m], eta, 64)) < 3e-3


def test_material_rows_keep_the_shader_kinds():
    rows = material_table(SimpleNamespace(materials=Materials.make([
        dict(shader=MATERIAL_GLOSSY, transmission=1.0), dict(shader=MATERIAL_GLASS, metallic=1.0),
        dict(specular_ior_level=0.0)]), textures=[]))
    assert rows.dtype == MATERIAL_DTYPE
    np.testing.assert_array_equal(rows["metallic"], [1.0, 0.0, 0.0])
    np.testing.assert_array_equal(rows["transmission"], [0.0, 1.0, 0.0])
    np.testing.assert_array_equal(rows["specular_tint"][:, 3], [1.0, 1.0, 1.0])  # no specular layer


@pytest.mark.parametrize("row, glossy, specular", [
    (dict(metallic=1.0, roughness=0.0), False, True),  # a mirror: singular, a caustic caster
    (dict(metallic=1.0, roughness=0.05), True, True),  # near-specular: glossy and a caustic caster
    (dict(transmission=1.0, roughness=0.5), True, False),  # rough glass: glossy light, no caustic map
    (dict(specular_ior_level=0.5, roughness=0.5), True, False),  # plastic
    (dict(), False, False),  # Lambert
])
def test_the_scene_says_which_lobes_it_needs(row, glossy, specular):
    scene = make_scene(quad((0, 0, 0), 1.0), [0, 0], Materials.make([row]), Lights.make([]), camera_looking_down())
    assert scene.has_glossy() == glossy
    assert scene.has_specular() == specular
