"""Surface mesh, kernel interpolation, tactile surface and z-buffered frames."""

import numpy as np
import pytest

from tactile_flow.tactile import _frame_kernels, frames, surface, synthetic
from tactile_flow.tactile.frames import View


def test_mesh_covers_the_contact_half_evenly(model):
    mesh = model.mesh
    assert np.all(mesh.local_points[:, 2] <= 1e-9)                  # contact side only
    edges = np.concatenate([mesh.triangles[:, [0, 1]], mesh.triangles[:, [1, 2]], mesh.triangles[:, [2, 0]]])
    lengths = np.linalg.norm(mesh.points[edges[:, 0]] - mesh.points[edges[:, 1]], axis=1)
    assert lengths.max() < 2.5 * model.config.mesh_spacing
    # Outward orientation: face normals agree with the surface normals.
    p = mesh.points[mesh.triangles]
    fn = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    assert np.all(np.einsum("ij,ij->i", fn, mesh.normals[mesh.triangles].mean(1)) > 0)


def test_interpolation_reproduces_a_constant_and_peaks_at_the_pressed_taxel(model):
    w = model.weights
    assert np.allclose(w.sum(axis=1), 1.0)
    values = surface.interpolate(np.full(24, 3.0), w)
    assert np.allclose(values, 3.0)
    one = np.zeros(24)
    one[20] = 1.0                                                   # taxel 21 on the pad
    values = surface.interpolate(one, w)
    peak = model.mesh.points[np.argmax(values)]
    assert np.linalg.norm(peak[:2] - model.taxels[20, :2]) < 1.5


def test_tactile_surface_moves_along_normals(model):
    mesh = model.mesh
    disp = surface.tactile_surface(mesh, np.full(mesh.n_vertices, 2.0), scale=0.5)
    assert np.allclose(np.linalg.norm(disp - mesh.points, axis=1), 1.0)
    assert np.allclose(np.einsum("ij,ij->i", disp - mesh.points, mesh.normals), 1.0)


def test_frame_interpolates_linear_fields_exactly(model):
    plan = model.plans["bottom"]
    x = model.mesh.points[:, 0]
    img = frames.render(plan, model.mesh, x[None], scale=0.0)[0]
    cols = plan.origin[0] + plan.mm_per_px * np.arange(plan.shape[1])
    expected = np.broadcast_to(cols, plan.shape)
    assert plan.mask.any(axis=0).sum() >= 0.8 * plan.shape[1]       # the footprint fills the frame
    assert np.allclose(img[plan.mask], expected[plan.mask], atol=1e-4)
    assert np.all(img[~plan.mask] == 0)


def test_zbuffer_shows_the_nearest_surface(model):
    """A view that sees both halves must show the half nearer the camera."""
    mesh = model.mesh
    side = np.sign(mesh.local_points[:, 1])                          # −1 on y<0, +1 on y>0
    plan = frames.make_frame_plan(mesh, View("left_all", look=(0, 1, 0), up=(0, 0, 1), half="all"))
    img = frames.render(plan, mesh, side[None], scale=0.0)[0]
    inner = plan.mask & (np.abs(img) > 0)
    assert np.mean(img[inner] < 0) > 0.97                             # the y<0 half is in front


def test_displacement_pushes_the_silhouette_outward(model):
    plan, mesh = model.plans["bottom"], model.mesh
    flat = frames.render(plan, mesh, np.full((1, mesh.n_vertices), 2.0), scale=0.0)[0]
    bulged = frames.render(plan, mesh, np.full((1, mesh.n_vertices), 2.0), scale=0.5)[0]
    assert (bulged > 0).sum() > (flat > 0).sum()
    centre = tuple(s // 2 for s in plan.shape)
    assert bulged[centre] == pytest.approx(2.0)


def test_fixed_intensity_scale_keeps_brightness_comparable():
    a = frames.to_uint8(np.full((1, 4, 4), 1.0), 0.0, 4.0)
    b = frames.to_uint8(np.full((1, 4, 4), 2.0), 0.0, 4.0)
    assert int(b[0, 0, 0]) == 2 * int(a[0, 0, 0]) - 0 or abs(int(b[0, 0, 0]) - 2 * int(a[0, 0, 0])) <= 1
    assert a[0, 0, 0] != b[0, 0, 0]                                   # no per-frame normalisation
    with pytest.raises(ValueError, match="intensity range"):
        frames.to_uint8(np.zeros((1, 4, 4)), 1.0, 1.0)


@pytest.mark.parametrize("shape", [(), (7,), (3, 5, 6), (2, 0, 4)])
def test_to_uint8_rounds_half_to_even_and_saturates_for_any_shape(shape):
    """8-bit frames are (value − low)·255/(high − low) in float32, rounded half to even and
    clipped to 0..255, whatever the array's shape, order or dtype."""
    assert frames.to_uint8([0.5, 1.5, 2.5, -1.0, 300.0], 0.0, 255.0).tolist() == [0, 2, 2, 0, 255]
    values = np.random.default_rng(1).uniform(-5.0, 45.0, shape)
    for given in (values, values.astype(np.float32), np.asarray(values, order="F")):
        expected = np.clip(np.rint((given.astype(np.float32) - np.float32(0)) * np.float32(255 / 40)), 0, 255)
        got = frames.to_uint8(given, 0.0, 40.0)
        assert got.dtype == np.uint8 and got.shape == shape
        assert np.array_equal(got, expected.astype(np.uint8))


def test_default_views_axes():
    cols, rows, look = frames.view_axes(frames.DEFAULT_VIEWS["bottom"])
    assert np.allclose([cols, rows, look], [[1, 0, 0], [0, 1, 0], [0, 0, 1]])
    for name in ("left", "right"):
        c, r, l = frames.view_axes(frames.DEFAULT_VIEWS[name])
        assert np.allclose(np.cross(c, r), l) and np.allclose(r, [0, 0, -1])


def test_bad_frame_input(model):
    with pytest.raises(ValueError, match="size"):
        frames.make_frame_plan(model.mesh, frames.DEFAULT_VIEWS["bottom"], size=(4, 32))
    with pytest.raises(ValueError, match="too small"):
        frames.make_frame_plan(model.mesh, frames.DEFAULT_VIEWS["bottom"], size=(16, 16), mm_per_px=0.2)
    with pytest.raises(ValueError, match="up"):
        frames.view_axes(View("bad", look=(0, 0, 1), up=(0, 0, 2)))
    with pytest.raises(ValueError, match="values"):
        frames.render(model.plans["bottom"], model.mesh, np.zeros((2, 5)), scale=0.0)
    with pytest.raises(ValueError, match="values"):
        frames.render(model.plans["bottom"], model.mesh, np.full((1, model.mesh.n_vertices), np.nan), 0.0)
    with pytest.raises(ValueError, match="activation"):
        surface.interpolate(np.zeros(23), model.weights)


def _folding_cases(model, plan, rng):
    """(values, scale) pairs for one view: a sliding contact (no folds), the same contact
    three times deeper with 4× the displacement (folds), random vertex noise with a small
    displacement (a few triangles flip: pixel-by-pixel fallback) and a large one (many flip:
    whole-frame fallback), and the undisplaced surface."""
    k = len(plan.vertices)
    act = synthetic.moving_bump(model.taxels, start=(-8, -3, 0), velocity=(10, 4, 0), duration=1.6)
    contact = (act + rng.normal(0, 0.07, act.shape)) @ model.weights[plan.vertices].T
    return [(contact, 0.25), (3 * contact, 1.0), (rng.uniform(0, 8, (150, k)), 0.02),
            (rng.uniform(0, 8, (150, k)), 0.05), (rng.uniform(0, 8, (30, k)), 0.25),
            (rng.uniform(0, 8, (20, k)), 0.0)]


@pytest.mark.parametrize("view", ["bottom", "left", "right"])
def test_mesh_walk_renders_the_zbuffer_frames(model, rng, view):
    """The fast renderer (mesh walk, winding numbers, fallbacks) against the plain z-buffer."""
    plan, mesh = model.plans[view], model.mesh
    assert plan.walk is not None
    full = single = 0
    for values, scale in _folding_cases(model, plan, rng):
        fast, n_full, n_single = frames._render(plan, mesh, values, scale)
        ref, _, _ = frames._render(plan, mesh, values, scale, fast=False)
        np.testing.assert_allclose(fast, ref, rtol=0, atol=1e-6, err_msg=f"scale {scale}")
        lo_hi = (1.0, 5.0)                                           # clips at both ends
        assert np.array_equal(frames._render(plan, mesh, values, scale, lo_hi)[0],
                              frames.to_uint8(ref, *lo_hi))
        if scale == 0.0:
            assert n_full == n_single == 0                           # a flat mesh never folds
        full += n_full
        single += n_single
    assert full > 0 and single > 0                                   # both fallbacks were exercised


def test_mesh_walk_is_used_for_a_sliding_contact(model, rng):
    plan = model.plans["bottom"]
    values = _folding_cases(model, plan, rng)[0][0]
    _, n_full, n_single = frames._render(plan, model.mesh, values, 0.25)
    assert n_full == 0 and n_single < len(values)


def test_walk_index_topology(model):
    for plan in model.plans.values():
        nb, n_tri = plan.walk.neighbours, len(plan.triangles)
        inner = nb != _frame_kernels._NONE
        # Neighbourhood is symmetric and neighbours share the edge opposite the corner.
        for f, k in zip(*np.nonzero(inner)):
            g = nb[f, k]
            assert f in nb[g]
            edge = {plan.triangles[f, (k + 1) % 3], plan.triangles[f, (k + 2) % 3]}
            assert edge <= set(plan.triangles[g])
        assert (~inner).sum() == len(plan.walk.boundary) and nb[inner].max() < n_tri
    both = frames.make_frame_plan(model.mesh, View("left_all", look=(0, 1, 0), up=(0, 0, 1), half="all"))
    assert both.walk is None                                          # faces the camera both ways


def test_render_activation_equals_interpolate_then_render(model, rng):
    act = synthetic.moving_bump(model.taxels, start=(0, -4, 0), velocity=(0, 8, 0), duration=0.3)
    act = act + rng.normal(0, 0.07, act.shape)
    for plan in model.plans.values():
        ref = frames.render(plan, model.mesh, surface.interpolate(act, model.weights), 0.25)
        got = frames.render_activation(plan, model.mesh, model.weights, act, 0.25)
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-5)
        u8 = frames.render_activation(plan, model.mesh, model.weights, act, 0.25, (0.0, 8.0))
        assert u8.dtype == np.uint8 and np.abs(u8.astype(int) - frames.to_uint8(ref, 0.0, 8.0)).max() <= 1
    with pytest.raises(ValueError, match="activation"):
        frames.render_activation(model.plans["bottom"], model.mesh, model.weights, np.zeros((3, 23)), 0.25)


@pytest.mark.parametrize("n_taxels", [24, 7])
def test_vertex_values_are_the_taxel_order_sum_bit_for_bit(rng, n_taxels):
    """The renderer's interpolation adds the taxels in order, one product at a time, for
    every frame on its own: equal, bit for bit, to ((0 + a0·w0) + a1·w1) + … in NumPy,
    whether a frame is interpolated alone (as the live pipeline does) or among others."""
    weights = rng.random((n_taxels, 301))
    activation = rng.normal(1.0, 2.0, (5, n_taxels))
    expected = np.zeros((5, 301))
    for c in range(n_taxels):
        expected = expected + activation[:, c:c + 1] * weights[c]
    together, alone = np.empty((5, 301)), np.empty((1, 301))
    _frame_kernels._interpolate(activation, weights, together)
    assert np.array_equal(together, expected)
    for t in range(5):
        _frame_kernels._interpolate(activation[t:t + 1], weights, alone)
        assert np.array_equal(alone[0], expected[t])
