"""The diaphragm screen's and aiming camera's ``[effects]`` (seed 000), rendered, against closed
forms and exact traces. Each test fails when its effect is off (asserted values are the effect's)."""

import numpy as np
import pytest

from rigsim.frames import from_arcsec
from rigsim.imaging.screen import pixel_area_mm2, screen_centroid
from rigsim.optics.cube_ghosts import normal_reflectance, slab_reflectance
from rigsim.render.cube_mirror import diaphragm as D
from rigsim.rig import load_rig
from rigsim.truth.cube_mirror.realization import realization_from_rig

pytestmark = pytest.mark.render

BASE = load_rig("sun_sensor_2axis_diaphragm")
# the 768 × 576 camera of the diaphragm renderer's own tests (same optics and pixel)
BASE = BASE.model_copy(update={"aiming_camera": BASE.aiming_camera.model_copy(update={"resolution_px": [768, 576]})})


def _with(rig, name, **update):
    e = getattr(rig.effects, name).model_copy(update={"enabled": True, **update})
    return rig.model_copy(update={"effects": rig.effects.model_copy(update={name: e})})


def _pose(geom, **arcsec):
    p = dict(geom.layout.null_pose_rad)
    for ax, a in arcsec.items():
        p[ax] += from_arcsec(a)
    return p


def _screen_grid(g):
    W, H = g.camera.width, g.camera.height
    uv = np.stack(np.meshgrid(np.arange(W, dtype=float), np.arange(H, dtype=float)), -1).reshape(-1, 2)
    return g.uv_to_screen(uv).reshape(H, W, 2), pixel_area_mm2(g, uv).reshape(H, W)


def _disk(st, c, r):
    return np.hypot(st[..., 0] - c[0], st[..., 1] - c[1]) < r


# -- cube ghosts ------------------------------------------------------------------------------------
def test_cube_ghost_lands_where_the_exact_trace_puts_it_with_the_fresnel_power():
    """A glass cube whose back face is tilted 400″: the first ghost lands 3.9 mm from the spot, where
    the Snell trace puts it (to 1 µm, relative to the direct spot), carrying (1−R)²·R_back of the
    beam: 0.917 of the direct spot's R (Fresnel, unpolarised), to 1 %."""
    rig = _with(BASE, "cube_ghosts", back_face_tilt_arcsec={"-Z": [0.0, 400.0, 0.0]})
    r = D.DiaphragmRenderer(rig, realization_from_rig(rig), 0, spp=16, return_into_hole="diffuse",
                            deterministic=False, warmup=False)
    g = r.geometry
    pose = _pose(g, X=-100.0)
    ph, _, _ = r.render_photons(pose, seed=3, hole=False)
    st, area = _screen_grid(g)
    (c0, p0), (c1, p1) = D.ghost_spot(g, pose, 0), D.ghost_spot(g, pose, 1)
    assert np.allclose(c0, g.trace(pose).offset_mm, atol=1e-9)  # order 0 is the mirror reflection
    assert np.linalg.norm(c1 - c0) > 3.5  # apart: two whole disks of 2.5 mm
    m0, m1 = _disk(st, c0, 1.6), _disk(st, c1, 1.6)
    rel_um = 1e3 * ((screen_centroid(ph, g, mask=m1) - screen_centroid(ph, g, mask=m0)) - (c1 - c0))
    print("ghost − spot, rendered − traced (µm):", rel_um)
    assert np.linalg.norm(rel_um) < 1.0
    ratio = (ph * area * m1).sum() / (ph * area * m0).sum()
    print(f"ghost / spot power: rendered {ratio:.4f}, Fresnel {p1 / p0:.4f}")
    assert ratio == pytest.approx(p1 / p0, rel=0.01)
    assert p1 / p0 == pytest.approx((1 - normal_reflectance(1.5168)) ** 2, rel=1e-3)


def test_cube_ghost_pulls_the_spot_by_its_power_weighted_share():
    """The rig's default 3″ wedge: the ghost overlaps the spot; their joint centroid sits at the
    power-weighted mean of the two traced centres (≈ 14 µm, about one object pixel, from the
    spot alone). The plateau is kept: the exposure divides by the cube's total reflectance."""
    rig = _with(BASE, "cube_ghosts")
    r = D.DiaphragmRenderer(rig, realization_from_rig(rig), 0, spp=16, return_into_hole="diffuse",
                            deterministic=False, warmup=False)
    g = r.geometry
    pose = _pose(g, X=-100.0)
    ph, _, _ = r.render_photons(pose, seed=5, hole=False)
    (c0, p0), (c1, p1) = D.ghost_spot(g, pose, 0), D.ghost_spot(g, pose, 1)
    expected = (p0 * c0 + p1 * c1) / (p0 + p1)
    st, _ = _screen_grid(g)
    got = screen_centroid(ph, g, mask=_disk(st, c0, 2.0))
    shift_um = 1e3 * (got - c0)
    print("joint centroid − spot (µm):", shift_um, "expected", 1e3 * (expected - c0))
    assert np.linalg.norm(1e3 * (expected - c0)) > 10.0
    assert np.linalg.norm(1e3 * (got - expected)) < 1.5
    assert r.photons_per_radiance == pytest.approx(
        r.spot_photons_per_px / D.spot_radiance(r.screen_reflectance, 1.0)
        / slab_reflectance(normal_reflectance(1.5168), 1), rel=1e-12)
