"""Rough dielectric transmittance T and diffuse Fresnel reflectance Fdr (Mitsuba 0.6 rtrans)."""

from __future__ import annotations

import numpy as np
import pytest

import matremap.renderers.embedded.rough_transmittance as rt
from matremap.core.optics import fresnel_dielectric
from matremap.renderers.embedded import microfacet as mf

# tables are built once per distribution into a throw-away cache directory; phong is only
# exercised on small grids (see ``small_tables``) to keep the file fast
DISTS = ("beckmann", "ggx")


@pytest.fixture(scope="module", autouse=True)
def _isolated_cache(tmp_path_factory):
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("MATREMAP_CACHE", str(tmp_path_factory.mktemp("matremap-cache")))
        rt._tables.cache_clear()
        yield
    rt._tables.cache_clear()


@pytest.fixture
def small_tables(monkeypatch, tmp_path):
    """Tiny grids (fast to build) in a fresh cache directory; the in-memory cache is cleared
    before and after so that no other test sees these tables."""
    monkeypatch.setattr(rt, "_N_MU", 12)
    monkeypatch.setattr(rt, "_N_ALPHA", 8)
    monkeypatch.setattr(rt, "_N_ETA", 6)
    monkeypatch.setenv("MATREMAP_CACHE", str(tmp_path / "cache"))
    rt._tables.cache_clear()
    yield tmp_path / "cache"
    rt._tables.cache_clear()


def _gauss(n, lo, hi):
    x, w = np.polynomial.legendre.leggauss(n)
    return lo + (hi - lo) * 0.5 * (x + 1.0), 0.5 * (hi - lo) * w


def _smooth_fdr(eta: float) -> float:
    """1 - integral (1 - F(mu, eta)) 2 mu dmu by Gauss quadrature in t = mu^2, starting at the
    critical cosine (with a square-root substitution) when eta < 1."""
    t_c = max(1.0 - eta * eta, 0.0)
    s, w = _gauss(200, 0.0, 1.0)
    t = t_c + (1.0 - t_c) * s * s
    return 1.0 - float(np.sum((1.0 - fresnel_dielectric(np.sqrt(t), eta)) * 2.0 * (1.0 - t_c) * s * w))


def _brute_force(dist, mu, alpha, eta, n=400):
    """T by a plain midpoint rule over the microfacet hemisphere, straight from the definition
    (D, rational/exact Smith G1, Fresnel, refraction), independent of the module's quadrature."""
    th = (np.arange(n) + 0.5) * (0.5 * np.pi / n)
    ph = (np.arange(2 * n) + 0.5) * (np.pi / (2 * n))  # phi in [0, pi]; the integrand is even in phi
    TH, PH = np.meshgrid(th, ph, indexing="ij")
    m = np.stack([np.sin(TH) * np.cos(PH), np.sin(TH) * np.sin(PH), np.cos(TH)], axis=-1)
    i = np.array([np.sqrt(1.0 - mu * mu), 0.0, mu])
    c = m @ i
    d = (mf.d_beckmann if dist == "beckmann" else mf.d_ggx)(np.cos(TH), np.tan(TH) ** 2, alpha)
    g1 = mf.g1_beckmann_rational if dist == "beckmann" else mf.g1_ggx
    with np.errstate(all="ignore"):
        cos_t = np.sqrt(np.maximum(1.0 - (1.0 - c * c) / eta**2, 0.0))
        o = (c / eta - cos_t)[..., None] * m - i / eta  # refract(i, m)
        oz = o[..., 2]
        g = g1(np.sqrt(1.0 - mu * mu) / mu, alpha) * g1(np.sqrt(np.maximum(1.0 - oz * oz, 0.0)) / -oz, alpha)
        f = np.where((c > 0) & (oz < 0) & (cos_t > 0), d * g * c * (1.0 - fresnel_dielectric(c, eta)) / mu, 0.0)
    return 2.0 * float(np.sum(f * np.sin(TH))) * (0.5 * np.pi / n) * (np.pi / (2 * n))


# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("dist", DISTS)
@pytest.mark.parametrize("eta", [1.5, 1.33, 2.4, 1 / 1.5, 1 / 1.33])
def test_smooth_limit_is_one_minus_fresnel(dist, eta):
    mu = np.array([0.1, 0.3, 0.6, 0.8, 0.95, 1.0])
    for alpha in (0.0, 1e-4):  # alpha is clamped to 1e-4, as in Mitsuba
        t = rt.transmittance(dist, mu, alpha, eta)
        np.testing.assert_allclose(t, 1.0 - fresnel_dielectric(mu, eta), atol=1e-3)


@pytest.mark.parametrize("dist", DISTS)
def test_matches_independent_brute_force_integration(dist):
    for mu, alpha, eta in [(0.5, 0.3, 1.5), (0.05, 0.5, 2.0), (0.2, 0.8, 1.33), (0.9, 0.4, 1 / 1.5)]:
        ref = _brute_force(dist, mu, alpha, eta)
        assert abs(float(rt.transmittance(dist, mu, alpha, eta)) - ref) < 1e-3, (mu, alpha, eta)


@pytest.mark.parametrize("dist", DISTS)
def test_interpolation_matches_direct_integration_off_grid(dist):
    """Random off-grid points against the direct integral, within the documented accuracy:
    1e-3 outside (eta' >= 1.2) and 1.5e-3 inside away from the critical angle."""
    rng = np.random.default_rng(2024)
    n = 40
    mu = rng.uniform(0.0, 1.0, n) ** 1.5
    alpha = np.exp(rng.uniform(np.log(1e-4), np.log(2.0), n))
    etap = rng.uniform(1.2, 3.0, n)
    ref_out = np.clip(rt.transmittance_direct(dist, mu, alpha, etap), 0.0, 1.0)
    assert np.max(np.abs(rt.transmittance(dist, mu, alpha, etap) - ref_out)) < 1e-3
    keep = np.abs(mu - np.sqrt(1.0 - 1.0 / etap**2)) > 0.05
    ref_in = np.clip(rt.transmittance_direct(dist, mu[keep], alpha[keep], 1.0 / etap[keep]), 0.0, 1.0)
    assert np.max(np.abs(rt.transmittance(dist, mu[keep], alpha[keep], 1.0 / etap[keep]) - ref_in)) < 1.5e-3


# values read from Mitsuba 0.6's data/microfacet/{beckmann,ggx}.dat at their own grid nodes
# (mu = (i/99)^4, alpha = 4 (j/49)^4, eta = 1.0001 + 2.9999 (k/49)^4, in single precision)
MITSUBA_T = [
    ("beckmann", 0.24994899332523346, 0.2710414230823517, 1.42160964012146, 0.81176),
    ("beckmann", 0.026650119572877884, 0.8228702545166016, 1.0833611488342285, 0.41917),
    ("ggx", 0.1349162608385086, 0.5620315670967102, 1.2033742666244507, 0.56951),
    ("ggx", 0.5434190630912781, 1.041232943534851, 1.780998706817627, 0.62979),
]
MITSUBA_FDR = [  # 1 - evalDiffuse; eta < 1 is the internal block used by roughplastic
    ("beckmann", 0.3170801103115082, 0.6753635834249063, 0.57964),
    ("beckmann", 0.3170801103115082, 1 / 0.6753635834249063, 0.07806),
    ("beckmann", 0.8228702545166016, 0.9230532229036172, 0.19924),
    ("ggx", 0.8228702545166016, 1 / 0.9230532229036172, 0.18277),
]


@pytest.mark.parametrize("dist, mu, alpha, eta, expected", MITSUBA_T)
def test_matches_mitsuba_tables(dist, mu, alpha, eta, expected):
    assert abs(float(rt.transmittance(dist, mu, alpha, eta)) - expected) < 1e-3


@pytest.mark.parametrize("dist, alpha, eta, expected", MITSUBA_FDR)
def test_fdr_matches_mitsuba_tables(dist, alpha, eta, expected):
    assert abs(float(rt.diffuse_fresnel_reflectance(dist, alpha, eta)) - expected) < 1e-3


@pytest.mark.parametrize("dist", DISTS)
@pytest.mark.parametrize("eta", [1.5, 1 / 1.5])
def test_fdr_small_alpha_is_smooth_diffuse_fresnel(dist, eta):
    smooth = _smooth_fdr(eta)
    assert abs(float(rt.diffuse_fresnel_reflectance(dist, 1e-4, eta)) - smooth) < 1e-3
    # both sides of a smooth interface are tied by 1 - Fdr(1/eta) = (1 - Fdr(eta)) / eta^2
    # (a check of the reference quadrature)
    assert abs((1.0 - _smooth_fdr(1.0 / eta)) - (1.0 - _smooth_fdr(eta)) / eta**2) < 1e-6


@pytest.mark.parametrize("dist", DISTS)
@pytest.mark.parametrize("eta", [1.49, 1 / 1.49, 2.5, 1 / 2.5])
def test_fdr_is_the_cosine_weighted_average_of_t(dist, eta):
    mu_c = np.sqrt(max(1.0 - eta * eta, 0.0))
    for alpha in (0.01, 0.2, 0.7):
        total = 0.0
        for lo, hi in ((0.0, mu_c), (mu_c, 1.0)):
            mu, w = _gauss(64, lo, hi)
            total += float(np.sum(rt.transmittance(dist, mu, alpha, eta) * 2.0 * mu * w))
        assert abs(float(rt.diffuse_fresnel_reflectance(dist, alpha, eta)) - (1.0 - total)) < 1e-3


@pytest.mark.parametrize("dist", DISTS)
def test_values_are_finite_and_in_unit_interval(dist):
    rng = np.random.default_rng(7)
    mu = np.concatenate([[0.0, 1e-12, 1e-6, 1.0], rng.uniform(0.0, 1.0, 300)])
    alpha = np.concatenate([[0.0, 1e-5, 4.0, 10.0], np.exp(rng.uniform(np.log(1e-5), np.log(5.0), 300))])
    eta = np.concatenate([[1.0, 0.05, 10.0, 1.0001], np.exp(rng.uniform(-1.5, 1.5, 300))])
    t = rt.transmittance(dist, mu, alpha, eta)
    assert np.all(np.isfinite(t)) and np.all((t >= 0.0) & (t <= 1.0))
    fdr = rt.diffuse_fresnel_reflectance(dist, alpha, eta)
    assert np.all(np.isfinite(fdr)) and np.all((fdr >= 0.0) & (fdr <= 1.0))
    assert np.all(np.isnan(rt.transmittance(dist, [np.nan, 0.5, 0.5], [0.1, np.nan, 0.1], [1.5, 1.5, np.nan])))


@pytest.mark.parametrize("dist", DISTS)
def test_physically_expected_trends(dist):
    mu = np.linspace(0.02, 1.0, 60)
    # nearly smooth: more transmission towards normal incidence
    assert np.all(np.diff(rt.transmittance(dist, mu, 0.02, 1.5)) > -1e-4)
    # a denser medium reflects more at normal incidence
    assert np.all(np.diff(rt.transmittance(dist, 1.0, 0.1, np.linspace(1.1, 3.5, 25))) < 0)
    # inside, below the critical angle, a smooth interface transmits (next to) nothing
    assert np.all(rt.transmittance(dist, np.linspace(0.05, 0.6, 12), 1e-3, 1 / 1.5) < 1e-4)
    # roughness tilts facets towards grazing light: more transmission there
    assert rt.transmittance(dist, 0.05, 0.3, 1.5) > rt.transmittance(dist, 0.05, 1e-3, 1.5) + 0.1
    # shadowing-masking losses are not transmitted: T < 1 even without an interface (eta = 1)
    assert rt.transmittance(dist, 0.3, 1.0, 1.0) < 0.95


@pytest.mark.parametrize("dist", DISTS)
def test_broadcasting_and_both_evaluation_paths_agree(dist):
    rng = np.random.default_rng(3)
    cos = rng.uniform(0.0, 1.0, (4, 50, 1))
    alpha = rng.uniform(0.01, 1.0, (3, 1, 1, 1))
    eta = np.array([1.5, 1 / 1.3, 2.2]).reshape(3, 1, 1, 1)
    t = rt.transmittance(dist, cos, alpha, eta)  # few (alpha, eta) pairs: mu-curve path
    assert t.shape == (3, 4, 50, 1)
    flat = [np.broadcast_to(v, t.shape).ravel() for v in (cos, alpha, eta)]
    np.testing.assert_allclose(rt.transmittance(dist, *flat), t.ravel(), rtol=0, atol=1e-12)  # per-point path
    assert rt.transmittance(dist, 0.5, 0.2, 1.5).shape == ()
    # a negative cosine is light from the other side
    np.testing.assert_allclose(rt.transmittance(dist, -cos, 0.2, 1.5), rt.transmittance(dist, cos, 0.2, 1 / 1.5))
    assert rt.diffuse_fresnel_reflectance(dist, alpha, eta).shape == (3, 1, 1, 1)


def test_unknown_distribution():
    with pytest.raises(ValueError):
        rt.transmittance("blinn", 0.5, 0.1, 1.5)


def test_disk_cache_is_written_and_reused(small_tables, monkeypatch):
    args = (np.linspace(0.01, 1.0, 7), 0.3, np.array([[1.5], [1 / 1.5]]))
    small_tables.mkdir(parents=True)
    stale = small_tables / "rough_transmittance_phong_000000000000.npz"  # another grid version
    stale.write_bytes(b"old")
    first = rt.transmittance("phong", *args)
    assert not stale.exists()
    fdr = rt.diffuse_fresnel_reflectance("phong", 0.3, 1 / 1.5)
    files = list(small_tables.glob("rough_transmittance_phong_*.npz"))
    assert len(files) == 1 and not list(small_tables.glob("*.tmp"))
    # from disk, not rebuilt
    rt._tables.cache_clear()
    monkeypatch.setattr(rt, "_build", lambda d: pytest.fail("tables rebuilt instead of loaded"))
    np.testing.assert_array_equal(rt.transmittance("phong", *args), first)
    np.testing.assert_array_equal(rt.diffuse_fresnel_reflectance("phong", 0.3, 1 / 1.5), fdr)
    np.testing.assert_array_equal(rt.transmittance("as", *args), first)  # 'as' is phong
    # a corrupt file is rebuilt (and replaced)
    monkeypatch.undo()
    monkeypatch.setattr(rt, "_N_MU", 12)
    monkeypatch.setattr(rt, "_N_ALPHA", 8)
    monkeypatch.setattr(rt, "_N_ETA", 6)
    monkeypatch.setenv("MATREMAP_CACHE", str(small_tables))
    files[0].write_bytes(b"not a npz file")
    rt._tables.cache_clear()
    np.testing.assert_array_equal(rt.transmittance("phong", *args), first)
    assert files[0].stat().st_size > 1000


def test_unwritable_cache_dir_is_not_fatal(small_tables, monkeypatch, tmp_path):
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    monkeypatch.setenv("MATREMAP_CACHE", str(blocker / "cache"))  # cannot be created
    t = rt.transmittance("beckmann", np.linspace(0.0, 1.0, 5), 0.2, 1.5)
    assert np.all(np.isfinite(t)) and np.all((t >= 0) & (t <= 1))
    assert blocker.is_file()


def test_a_probes_cosines_give_the_same_transmittance_from_the_cache_and_it_stays_bounded():
    """Read-only cosine arrays (a probe's geometry) have their mu terms kept (rt._mu_terms): the values are those
    of a writeable copy, bit for bit, on both sides of the interface; a writeable array or a read-only view of
    one is not cached; the cache holds at most MU_TERMS_SIZE arrays."""
    rng = np.random.default_rng(4)
    mu = rng.uniform(0.0, 1.0, (1, 500))
    mu[0, :3] = (0.0, 1.0, 1e-9)
    frozen = mu.copy()
    frozen.flags.writeable = False
    for alpha, eta in ((0.2, 1.6), (0.05, 1 / 1.6), (np.array([[[[0.3]]], [[[0.7]]]]), 1.3)):
        first = rt.transmittance("ggx", frozen, alpha, eta)
        again = rt.transmittance("ggx", frozen, alpha, eta)
        plain = rt.transmittance("ggx", mu.copy(), alpha, eta)
        assert np.array_equal(first, plain) and np.array_equal(again, plain)
    assert rt._mu_terms(mu) is None and rt._mu_terms(mu[:, :10].view()) is None
    for _ in range(3 * rt.MU_TERMS_SIZE):
        other = rng.uniform(0.0, 1.0, (1, 50))
        other.flags.writeable = False
        rt.transmittance("beckmann", other, 0.3, 1.5)
    assert len(rt._MU_TERMS) <= rt.MU_TERMS_SIZE
