"""Tests of tactile.geometry: taxels, ellipsoid fit, geodesic distances, cache, kernel."""

import warnings

import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp
from scipy.optimize import least_squares
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from tactile_flow.tactile import disk_cache, geometry
from tactile_flow.tactile.geometry import (
    EllipsoidFit, cached_geodesic_distances, ellipsoid_angles, ellipsoid_normals,
    ellipsoid_points, fit_ellipsoid, geodesic_distances, geodesic_path, kernel_weights,
    load_taxels, project_to_ellipsoid, taxel_angles,
)

# Close to the ellipsoid fitted to the BioTac SP taxels (a > b > c, triaxial).
AXES = np.array([12.0, 7.8, 7.0])
A, B, C = AXES


def lower_half_points(rng, n, axes=AXES):
    """n random points on the contact-side half (z < 0) of the ellipsoid."""
    v = rng.normal(size=(n, 3))
    v[:, 2] = -np.abs(v[:, 2])
    return v / np.linalg.norm(v, axis=1, keepdims=True) * axes


def ellipse_arc(p, q, t0, t1):
    """Arc length of (p sin t, q cos t) for t in [t0, t1], by quadrature."""
    return quad(lambda t: np.hypot(p * np.cos(t), q * np.sin(t)), t0, t1,
                epsabs=1e-13, epsrel=1e-13)[0]


def shoot_geodesic(axes, start, target, direction, length):
    """Length of the geodesic from start to target by integrating the geodesic ODE.

    Newton-type solve (least squares on the landing error) for the initial direction
    angle in the tangent plane and the arc length, starting from ``direction``.
    Returns (length, landing error in mm).
    """
    ia2 = 1.0 / axes**2

    def rhs(_, y):
        x, v = y[:3], y[3:]
        # Constrained to sum(x^2/a^2) = 1: x'' = -lambda grad F, unit speed preserved.
        lam = np.sum(v * v * ia2) / np.sum(x * x * ia2 * ia2)
        return np.r_[v, -lam * x * ia2]

    normal = start * ia2 / np.linalg.norm(start * ia2)
    e1 = direction - direction @ normal * normal
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(normal, e1)

    def landing(params):
        angle, s = params
        v0 = np.cos(angle) * e1 + np.sin(angle) * e2
        sol = solve_ivp(rhs, (0.0, s), np.r_[start, v0], method="DOP853",
                        rtol=1e-12, atol=1e-12)
        return sol.y[:3, -1] - target

    fit = least_squares(landing, [0.0, length], method="lm", xtol=1e-14, ftol=1e-14,
                        gtol=1e-14)
    return fit.x[1], float(np.linalg.norm(fit.fun))


# --------------------------------------------------------------------------- taxels and fit

def test_load_taxels_shape_and_mirror_symmetry():
    taxels = load_taxels()
    assert taxels.shape == (24, 3) and taxels.dtype == np.float64
    # Taxels 11-20 mirror 1-10 across the y = 0 plane.
    np.testing.assert_allclose(taxels[10:20] * [1, -1, 1], taxels[:10], atol=1e-12)
    assert np.all(taxels[:10, 1] < 0) and np.all(taxels[:, 2] < 0)


@pytest.mark.parametrize("half", ["full", "lower"])
def test_fit_recovers_known_ellipsoid(half):
    rng = np.random.default_rng(7)
    centre, axes = np.array([0.7, -0.4, 1.3]), np.array([11.0, 8.0, 6.5])
    theta = np.arccos(rng.uniform(-1, 1, 60))
    if half == "lower":
        theta = rng.uniform(np.pi / 2 + 0.15, np.pi, 60)  # all points below the centre
    phi = rng.uniform(-np.pi, np.pi, 60)
    points = ellipsoid_points(axes, theta, phi) + centre
    fit = fit_ellipsoid(points)
    np.testing.assert_allclose(fit.centre, centre, atol=1e-6)
    np.testing.assert_allclose(fit.axes, axes, atol=1e-6)
    assert fit.rms < 1e-6


def test_fit_real_taxels():
    taxels = load_taxels()
    fit = fit_ellipsoid(taxels)
    msg = f"centre {fit.centre}, axes {fit.axes}, rms {fit.rms:.4f} mm"
    assert isinstance(fit, EllipsoidFit)
    assert fit.rms < 0.1, msg                       # measured 0.087 mm
    assert abs(fit.centre[1]) < 1e-6, msg           # mirror symmetry carries over
    assert fit.axes[0] > fit.axes[1] > fit.axes[2], msg
    # All taxels lie on the contact-side half of the fitted ellipsoid.
    theta, phi = taxel_angles(fit, taxels)
    assert np.all(theta > np.pi / 2) and np.all(theta <= np.pi), msg
    # The parameters map back to the taxels within the fit's residuals.
    back = ellipsoid_points(fit.axes, theta, phi) + fit.centre
    residual = np.linalg.norm(back - taxels, axis=1)
    assert np.sqrt(np.mean(residual**2)) == pytest.approx(fit.rms, rel=1e-9), msg


# --------------------------------------------------------------------------- ellipsoid maps

def test_angles_points_round_trip_and_ranges():
    rng = np.random.default_rng(3)
    theta = rng.uniform(0, np.pi, 200)
    phi = rng.uniform(-np.pi, np.pi, 200)
    th, ph = ellipsoid_angles(AXES, ellipsoid_points(AXES, theta, phi))
    np.testing.assert_allclose(th, theta, atol=1e-12)
    np.testing.assert_allclose(ph, phi, atol=1e-12)
    # The pole of the pad and the phi = pi seam.
    th, ph = ellipsoid_angles(AXES, [[0, 0, -C], [-A, -0.0, 0]])
    assert th[0] == pytest.approx(np.pi) and ph[1] == pytest.approx(np.pi)


def test_normals_are_unit_and_perpendicular_to_the_surface():
    theta, phi, eps = np.array([0.3, 1.9, 2.8]), np.array([-2.0, 0.4, 3.0]), 1e-6
    p = ellipsoid_points(AXES, theta, phi)
    n = ellipsoid_normals(AXES, p)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-14)
    d_theta = ellipsoid_points(AXES, theta + eps, phi) - p
    d_phi = ellipsoid_points(AXES, theta, phi + eps) - p
    assert np.all(np.abs(np.sum(n * d_theta, axis=1)) < 1e-10)
    assert np.all(np.abs(np.sum(n * d_phi, axis=1)) < 1e-10)
    assert np.all(np.sum(n * p, axis=1) > 0)  # outward


def test_projection_is_the_closest_point():
    rng = np.random.default_rng(4)
    points = rng.normal(size=(300, 3)) * 6
    foot = project_to_ellipsoid(AXES, points)
    np.testing.assert_allclose(np.sum((foot / AXES) ** 2, axis=1), 1.0, atol=1e-12)
    # The offset is along the normal at the foot ...
    offset = points - foot
    normal = ellipsoid_normals(AXES, foot)
    tangential = offset - np.sum(offset * normal, axis=1, keepdims=True) * normal
    assert np.max(np.linalg.norm(tangential, axis=1)) < 1e-9
    # ... and no sampled surface point is closer.
    grid = ellipsoid_points(AXES, *np.meshgrid(np.linspace(0, np.pi, 200),
                                               np.linspace(-np.pi, np.pi, 400)))
    grid = grid.reshape(-1, 3)
    nearest = np.min(np.linalg.norm(points[:20, None] - grid[None], axis=2), axis=1)
    assert np.all(np.linalg.norm(offset[:20], axis=1) <= nearest + 1e-9)


# --------------------------------------------------------------------------- geodesics

# Principal sections are geodesics. Each case: two points on one section, and the arc
# between them as (p, q, t0, t1) for ellipse_arc; phi = 0/pi is the x-z section, phi =
# +-pi/2 the y-z section (both through the pad's pole), theta = pi/2 the equator.
SECTION_CASES = {
    "xz short": ((2.0, 0.0), (2.2, 0.0), (A, C, 2.0, 2.2)),
    "xz side to pole": ((np.pi / 2 + 0.1, 0.0), (np.pi - 0.2, 0.0),
                        (A, C, np.pi / 2 + 0.1, np.pi - 0.2)),
    "xz across pole": ((np.pi / 2 + 0.05, 0.0), (np.pi / 2 + 0.3, np.pi),
                       (A, C, np.pi / 2 + 0.05, 3 * np.pi / 2 - 0.3)),
    "xz tip to tip": ((np.pi / 2, 0.0), (np.pi / 2, np.pi), (A, C, np.pi / 2, 3 * np.pi / 2)),
    "yz across pole": ((np.pi / 2 + 0.2, np.pi / 2), (np.pi / 2 + 0.6, -np.pi / 2),
                       (B, C, np.pi / 2 + 0.2, 3 * np.pi / 2 - 0.6)),
    "yz side to side": ((np.pi / 2, np.pi / 2), (np.pi / 2, -np.pi / 2),
                        (B, C, np.pi / 2, 3 * np.pi / 2)),
    "equator": ((np.pi / 2, 0.0), (np.pi / 2, 1.2), (B, A, 0.0, 1.2)),
}


@pytest.mark.parametrize("case", list(SECTION_CASES))
def test_accurate_geodesic_matches_principal_section_arc(case):
    (ta, fa), (tb, fb), arc = SECTION_CASES[case]
    pa, pb = ellipsoid_points(AXES, ta, fa), ellipsoid_points(AXES, tb, fb)
    reference = ellipse_arc(*arc)
    d = geodesic_distances(AXES, pa, pb)[0, 0]
    # (That these arcs are the shortest paths is checked by the graph search below.)
    assert abs(d / reference - 1) < 1e-6, f"{case}: {d} vs arc {reference}"


def graph_distances(axes, pa, pb, n_cloud=30000, k=40):
    """Shortest paths through a dense k-nearest-neighbour graph of surface points.

    Independent of the method under test and global (it searches all routes, over the
    whole ellipsoid): an upper bound of the geodesic distance up to the chords' tiny
    shortfall, a fraction of a percent too long from the graph's zigzag.
    """
    i = np.arange(n_cloud) + 0.5
    z = 1 - 2 * i / n_cloud
    angle = np.pi * (1 + 5**0.5) * i  # Fibonacci sphere: near-uniform directions
    rho = np.sqrt(1 - z * z)
    cloud = np.stack([rho * np.cos(angle), rho * np.sin(angle), z], -1)
    nodes = np.vstack([pa, pb, cloud * axes])
    dist, idx = cKDTree(nodes).query(nodes, k=k)
    rows = np.repeat(np.arange(len(nodes)), k - 1)
    graph = coo_matrix((dist[:, 1:].ravel(), (rows, idx[:, 1:].ravel())),
                       shape=(len(nodes),) * 2)
    d = dijkstra(graph.tocsr(), directed=False, indices=np.arange(len(pa)))
    return d[:, len(pa):len(pa) + len(pb)]


def test_accurate_geodesic_is_the_shortest_path():
    rng = np.random.default_rng(12)
    sections = SECTION_CASES.values()
    pa = np.vstack([[ellipsoid_points(AXES, *a) for a, _, _ in sections],
                    lower_half_points(rng, 10)])
    pb = np.vstack([[ellipsoid_points(AXES, *b) for _, b, _ in sections],
                    lower_half_points(rng, 10)])
    accurate = np.diagonal(geodesic_distances(AXES, pa, pb))
    graph = np.diagonal(graph_distances(AXES, pa, pb))
    excess = graph / accurate - 1
    # No route the graph finds is shorter (beyond the chord shortfall of its edges, up to
    # ~0.7 mm long: (0.7 mm / 7 mm)^2 / 24 ~ 4e-4); its excess is the graph's zigzag.
    assert np.all(excess > -1e-3) and np.all(excess < 0.01), excess


def test_accurate_geodesic_against_ode_shooting():
    rng = np.random.default_rng(11)
    pa, pb = lower_half_points(rng, 40), lower_half_points(rng, 40)
    keep = np.linalg.norm(pa - pb, axis=1) > 0.5
    pa, pb = pa[keep][:24], pb[keep][:24]
    d = np.diagonal(geodesic_distances(AXES, pa, pb))
    errors = []
    for a, b, length in zip(pa, pb, d):
        path = geodesic_path(AXES, a, b)
        assert np.allclose(path[0], a) and np.allclose(path[-1], b)
        reference, landing = shoot_geodesic(AXES, a, b, path[1] - path[0], length)
        assert landing < 1e-8
        errors.append(abs(length / reference - 1))
    median, worst = np.median(errors), np.max(errors)
    msg = f"relative error vs ODE shooting: median {median:.2e}, max {worst:.2e}"
    assert median <= 1e-3 and worst <= 5e-3, msg  # the requirement
    assert median <= 1e-6 and worst <= 1e-4, msg  # what the method achieves


def test_accurate_geodesic_metric_properties():
    rng = np.random.default_rng(5)
    p = lower_half_points(rng, 30)
    d = geodesic_distances(AXES, p, p)
    assert np.all(np.diagonal(d) == 0)
    np.testing.assert_allclose(d, d.T, rtol=1e-7, atol=1e-9)
    chord = np.linalg.norm(p[:, None] - p[None], axis=2)
    assert np.all(d >= chord - 1e-9)
    # Triangle inequality over all triples.
    via = d[:, :, None] + d[None, :, :]   # d(i, j) + d(j, k) -> [i, j, k]
    assert np.all(d[:, None, :] <= via + 1e-7 * d.max())


def test_paper_method_follows_the_parameter_straight_path():
    theta0 = 2.3
    pa, pb = ellipsoid_points(AXES, theta0, 0.4), ellipsoid_points(AXES, theta0, 0.4 + np.pi / 2)
    # Straight in (theta, phi) = along the parallel (a sin theta0 cos phi, b sin theta0 sin phi).
    parallel = np.sin(theta0) * ellipse_arc(B, A, 0.4, 0.4 + np.pi / 2)
    paper = geodesic_distances(AXES, pa, pb, method="paper", n_steps=1000)[0, 0]
    assert paper == pytest.approx(parallel, rel=1e-6)
    # Default 100 steps is within the chord error.
    default = geodesic_distances(AXES, pa, pb, method="paper")[0, 0]
    assert default == pytest.approx(parallel, rel=1e-4)
    # Symmetric, and the phi difference goes the shorter way round (across phi = pi).
    pc, pd = ellipsoid_points(AXES, theta0, 3.0), ellipsoid_points(AXES, theta0, -3.0)
    d = geodesic_distances(AXES, [pc, pd], [pc, pd], method="paper")
    np.testing.assert_allclose(d, d.T)
    assert d[0, 1] == pytest.approx(np.sin(theta0) * ellipse_arc(B, A, 3.0, 2 * np.pi - 3.0),
                                    rel=1e-4)


def test_paper_method_is_too_long_near_the_pole_only():
    near_pole = ellipsoid_points(AXES, np.pi - 0.3, np.array([0.0, np.pi - 0.01]))
    paper = geodesic_distances(AXES, near_pole[0], near_pole[1], method="paper")[0, 0]
    accurate = geodesic_distances(AXES, near_pole[0], near_pole[1])[0, 0]
    assert paper / accurate - 1 > 0.2, (paper, accurate)
    far = ellipsoid_points(AXES, np.array([np.pi / 2 + 0.3, np.pi / 2 + 0.4]),
                           np.array([0.2, 0.35]))
    paper = geodesic_distances(AXES, far[0], far[1], method="paper")[0, 0]
    accurate = geodesic_distances(AXES, far[0], far[1])[0, 0]
    assert abs(paper / accurate - 1) < 0.01, (paper, accurate)


def test_geodesic_bad_input():
    good = ellipsoid_points(AXES, [2.0, 2.5], [0.1, 1.0])
    with pytest.raises(ValueError, match="points_a"):
        geodesic_distances(AXES, good * 1.01, good)
    with pytest.raises(ValueError, match="points_b"):
        geodesic_distances(AXES, good, good[:, :2])
    with pytest.raises(ValueError, match="points_b"):
        geodesic_distances(AXES, good, np.full((2, 3), np.nan))
    with pytest.raises(ValueError, match="axes"):
        geodesic_distances([12.0, -7.8, 7.0], good, good)
    with pytest.raises(ValueError, match="axes"):
        geodesic_distances([12.0, 7.8], good, good)
    with pytest.raises(ValueError, match="accurate.*paper"):
        geodesic_distances(AXES, good, good, method="dijkstra")
    with pytest.raises(ValueError, match="n_steps"):
        geodesic_distances(AXES, good, good, method="paper", n_steps=0)
    # Within the tolerance counts as on the surface.
    assert geodesic_distances(AXES, good * (1 + 1e-8), good).shape == (2, 2)


# --------------------------------------------------------------------------- cache

@pytest.fixture
def pair_sets():
    rng = np.random.default_rng(8)
    return lower_half_points(rng, 3), lower_half_points(rng, 4)


def test_cache_hit_skips_computation(tmp_path, pair_sets, monkeypatch):
    pa, pb = pair_sets
    first = cached_geodesic_distances(AXES, pa, pb, cache_dir=tmp_path)
    np.testing.assert_array_equal(first, geodesic_distances(AXES, pa, pb))

    def fail(*args, **kwargs):
        raise AssertionError("recomputed despite a valid cache file")

    monkeypatch.setattr(disk_cache, "geodesic_distances", fail)
    again = cached_geodesic_distances(AXES, pa, pb, cache_dir=tmp_path)
    np.testing.assert_array_equal(again, first)
    assert [p.suffix for p in tmp_path.iterdir()] == [".npz"]  # no temporary files left


@pytest.mark.parametrize("damage", ["garbage", "truncated", "wrong values"])
def test_damaged_cache_is_detected_and_rebuilt(tmp_path, pair_sets, damage):
    pa, pb = pair_sets
    good = cached_geodesic_distances(AXES, pa, pb, cache_dir=tmp_path)
    (path,) = tmp_path.iterdir()
    if damage == "garbage":
        path.write_bytes(b"not an npz file")
    elif damage == "truncated":
        path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    else:  # valid file, stale checksum
        with np.load(path) as data:
            checksum = data["checksum"]
        with open(path, "wb") as fh:
            np.savez(fh, distances=good + 1.0, checksum=checksum)
    with pytest.warns(RuntimeWarning, match="unusable"):
        rebuilt = cached_geodesic_distances(AXES, pa, pb, cache_dir=tmp_path)
    np.testing.assert_array_equal(rebuilt, good)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the rewritten file is sound
        again = cached_geodesic_distances(AXES, pa, pb, cache_dir=tmp_path)
    np.testing.assert_array_equal(again, good)


def test_crash_while_writing_leaves_no_cache_file(tmp_path, pair_sets, monkeypatch):
    pa, pb = pair_sets

    def crash(fh, **arrays):
        fh.write(b"PK\x03\x04 half a file")
        raise KeyboardInterrupt

    with monkeypatch.context() as patch:
        patch.setattr(np, "savez", crash)
        with pytest.raises(KeyboardInterrupt):
            cached_geodesic_distances(AXES, pa, pb, cache_dir=tmp_path)
    assert list(tmp_path.iterdir()) == []  # neither a half-written file nor a temporary
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        d = cached_geodesic_distances(AXES, pa, pb, cache_dir=tmp_path)
    np.testing.assert_array_equal(d, geodesic_distances(AXES, pa, pb))


def test_cache_key_depends_on_inputs(tmp_path, pair_sets):
    pa, pb = pair_sets
    cached_geodesic_distances(AXES, pa, pb, cache_dir=tmp_path)
    cached_geodesic_distances(AXES, pa, pb, method="paper", cache_dir=tmp_path)
    cached_geodesic_distances(AXES, pa, pb, method="paper", cache_dir=tmp_path, n_steps=50)
    cached_geodesic_distances(AXES, pa[:2], pb, cache_dir=tmp_path)
    assert len(list(tmp_path.glob("*.npz"))) == 4
    paper = cached_geodesic_distances(AXES, pa, pb, method="paper", cache_dir=tmp_path)
    np.testing.assert_array_equal(paper, geodesic_distances(AXES, pa, pb, method="paper"))


def test_geodesic_cache_key_is_the_one_files_were_written_under(pair_sets):
    # a changed key would make every lab PC recompute its kernel distances once, silently
    # (the digest is what the code before the ellipsoid fit's cache wrote)
    pa, pb = pair_sets
    assert disk_cache._cache_key(AXES, pa, pb, tags=(geometry.ALGORITHM_VERSION, "accurate", {})) == \
        "68841bbb91d1696d6adadacc75fe4bfbe9ac0db5375e1c7c99bc02ea4ff554fb"


def test_fit_cache_gives_the_fit_to_the_bit_and_skips_it_when_warm(tmp_path, monkeypatch):
    taxels = load_taxels()
    fresh = fit_ellipsoid(taxels)
    for _ in range(2):        # written, then read back
        cached = geometry.cached_fit_ellipsoid(taxels, cache_dir=tmp_path)
        np.testing.assert_array_equal(cached.centre, fresh.centre)
        np.testing.assert_array_equal(cached.axes, fresh.axes)
        assert cached.rms == fresh.rms

    def fail(*args, **kwargs):
        raise AssertionError("fitted again despite a valid cache file")

    monkeypatch.setattr(disk_cache, "fit_ellipsoid", fail)
    np.testing.assert_array_equal(geometry.cached_fit_ellipsoid(taxels, cache_dir=tmp_path).axes, fresh.axes)
    with pytest.raises(AssertionError, match="fitted again"):        # other points: another file
        geometry.cached_fit_ellipsoid(taxels[:20], cache_dir=tmp_path)


def test_damaged_fit_cache_is_reported_and_refitted(tmp_path):
    taxels = load_taxels()
    good = geometry.cached_fit_ellipsoid(taxels, cache_dir=tmp_path)
    (path,) = tmp_path.glob("ellipsoid-*.npz")
    path.write_bytes(b"not an npz file")
    with pytest.warns(RuntimeWarning, match="ellipsoid cache file .* unusable"):
        again = geometry.cached_fit_ellipsoid(taxels, cache_dir=tmp_path)
    np.testing.assert_array_equal(again.axes, good.axes)


def test_default_cache_dir(monkeypatch, tmp_path):
    monkeypatch.setenv("TACTILE_CACHE_DIR", str(tmp_path / "explicit"))
    assert geometry.default_cache_dir() == tmp_path / "explicit"
    monkeypatch.delenv("TACTILE_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert geometry.default_cache_dir() == tmp_path / "xdg" / "tactile-flow"
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert geometry.default_cache_dir() == tmp_path / "home" / ".cache" / "tactile-flow"


# --------------------------------------------------------------------------- kernel

@pytest.mark.parametrize("form", ["paper", "squared"])
def test_kernel_weights_normalised_and_decreasing(form):
    d = np.array([[0.0, 1.0, 2.0, 5.0], [3.0, 0.5, 8.0, 1.5]])
    w = kernel_weights(d, sigma=1.5, form=form)
    assert w.shape == d.shape
    np.testing.assert_allclose(w.sum(axis=1), 1.0, atol=1e-15)
    for row_d, row_w in zip(d, w):
        order = np.argsort(row_d)
        assert np.all(np.diff(row_w[order]) < 0)


def test_kernel_weights_formulas():
    d = np.array([[0.0, 1.0, 4.0]])
    raw = kernel_weights(d, sigma=2.0, form="paper", normalise=False)
    np.testing.assert_allclose(raw, np.exp(-d / 8.0))
    raw = kernel_weights(d, sigma=2.0, form="squared", normalise=False)
    np.testing.assert_allclose(raw, np.exp(-d**2 / 8.0))
    np.testing.assert_allclose(kernel_weights(d, 2.0), np.exp(-d / 8.0) / np.exp(-d / 8.0).sum())


def test_kernel_weights_do_not_underflow():
    # Every raw weight underflows to 0 here; the normalised ones must still be sound.
    d = np.array([[3000.0, 3001.0, 3005.0]])
    assert np.all(kernel_weights(d, 0.5, form="squared", normalise=False) == 0)
    w = kernel_weights(d, 0.5, form="squared")
    assert np.all(np.isfinite(w)) and w.sum() == pytest.approx(1.0)
    assert w[0, 0] == pytest.approx(1.0)


@pytest.mark.parametrize("sigma", [0.0, -1.0, np.nan, np.inf])
def test_kernel_weights_reject_bad_sigma(sigma):
    with pytest.raises(ValueError, match="sigma"):
        kernel_weights(np.ones((2, 24)), sigma)


def test_kernel_weights_reject_bad_distances_and_form():
    with pytest.raises(ValueError, match="distances"):
        kernel_weights(np.array([[1.0, np.nan]]), 1.0)
    with pytest.raises(ValueError, match="distances"):
        kernel_weights(np.array([[1.0, -0.1]]), 1.0)
    with pytest.raises(ValueError, match="form"):
        kernel_weights(np.ones((2, 3)), 1.0, form="gaussian")


def test_fit_and_maps_bad_input():
    with pytest.raises(ValueError, match="points"):
        fit_ellipsoid(load_taxels()[:5])
    with pytest.raises(ValueError, match="points"):
        fit_ellipsoid(np.full((10, 3), np.nan))
    with pytest.raises(ValueError, match="points"):
        fit_ellipsoid(np.ones((10, 2)))
    with pytest.raises(ValueError, match="theta"):
        ellipsoid_points(AXES, [np.nan], [0.0])
    with pytest.raises(ValueError, match="points"):
        ellipsoid_angles(AXES, [0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="points"):
        project_to_ellipsoid(AXES, [[1.0, 2.0]])
