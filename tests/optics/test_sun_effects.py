"""The sun sensor's effects without rendering: the disk's radiance (limb darkening, gradient) and
the cover glass (Fresnel, the ghost's offset), each against a closed form or an exact ray trace."""

import math

import numpy as np
import pytest

from rigsim.optics.camera import PinholeBrown
from rigsim.optics.cover_glass import CoverGlass, fresnel_rs_rp, glass_spots
from rigsim.optics.sun_disk import SIMULATOR_32ARCMIN_RAD as A
from rigsim.optics.sun_disk import spot_truth
from rigsim.optics.sun_radiance import DiskRadiance
from rigsim.rig import load_rig
from rigsim.rig.load import parse_rig

CAM = PinholeBrown(fx=3000.0, fy=3000.0, cx=1000.0, cy=1000.0, width=2000, height=2000)


def _cell_area(nr, nphi):
    r = np.linspace(0.0, 1.0, nr + 1)
    return np.diff(r * r / 2.0)[None, :] * np.full((nphi, 1), 2.0 * math.pi / nphi)


@pytest.mark.parametrize("u,g", [(0.6, 0.0), (0.0, 0.1), (0.6, 0.02), (1.0, 0.3)])
def test_texture_keeps_the_flux_and_the_first_moment(u, g):
    """The texture's cells hold exact means: the disk's flux is π (mean 1) to rounding, and the
    first moment along the gradient is g ∫ D r³ dr dφ / π, = g/4 for a uniform disk."""
    d = DiskRadiance(u, g)
    T = d.texture(512, 64)
    area = _cell_area(512, 64)
    assert (T * area).sum() == pytest.approx(math.pi, rel=1e-12)
    rr = (np.arange(20000) + 0.5) / 20000
    m1 = g * np.sum(d.limb(rr) * rr**3) / 20000 * math.pi / math.pi  # ∫ D r³ dr ∫cos² dφ / π
    phi = (np.arange(64) + 0.5) / 64 * 2 * math.pi
    assert np.isclose(np.sum(T * area * np.cos(phi)[:, None] * ((np.arange(512) + 0.5) / 512)[None, :]) / math.pi,
                      m1, rtol=2e-3, atol=1e-9)
    if u == 0.0:
        assert m1 == pytest.approx(g / 4.0, rel=1e-6)


def test_limb_darkening_law():
    """D(0) = 1/(1 − u/3), D(1) = (1 − u)/(1 − u/3): the Eddington law (2 + 3μ)/5 for u = 0.6."""
    d = DiskRadiance(0.6)
    assert d.limb(0.0) == pytest.approx(1.25)
    assert d.limb(1.0) == pytest.approx(0.5)
    r = np.array([0.3, 0.7, 0.95])
    assert np.allclose(d.limb(r) / d.limb(0.0), (2.0 + 3.0 * np.sqrt(1 - r * r)) / 5.0)
    # the texture is the cell mean: at fine cells it is the law at the cell's centre
    T = d.texture(4096)[0]
    c = (np.arange(4096) + 0.5) / 4096
    assert np.abs(T[:3000] - d.limb(c[:3000])).max() < 1e-6


def test_spot_truth_of_a_gradient_on_axis():
    """On axis through an undistorted pinhole the disk's image is the disk scaled: the centroid of a
    gradient 1 + g r cos φ moves by R g / 4 along the gradient, R = f tan(a/2)."""
    ax = np.array([0.6, -0.8, 0.0])
    t = spot_truth(CAM, [0, 0, 1.0], A, n=400_000, radiance=DiskRadiance(0.0, 0.1), radiance_axis=ax,
                   response="radiance")
    shift = np.subtract(t["mean_uv"], t["center_uv"])
    assert np.allclose(shift, 3000.0 * math.tan(A / 2) * 0.1 / 4 * ax[:2], atol=2e-5)


def test_limb_darkening_leaves_the_continuous_centroid():
    """The flux-weighted centroid through a pinhole is f·m_xy/m_z, m the mean direction (each
    direction's photons weigh cos θ, its image is f d_xy/d_z): for any radially symmetric disk m ∥ s,
    so limb darkening moves the continuous centroid by nothing, even 55° off axis."""
    for deg in (0.0, 30.0, 55.0):
        th = math.radians(deg)
        s = [math.sin(th) * 0.8, math.sin(th) * 0.6, math.cos(th)]
        a = spot_truth(CAM, s, A, n=400_000)
        b = spot_truth(CAM, s, A, n=400_000, radiance=DiskRadiance(0.6))
        assert np.abs(np.subtract(b["mean_uv"], b["center_uv"])).max() < 1e-4
        assert np.abs(np.subtract(b["mean_uv"], a["mean_uv"])).max() < 1e-4


def test_fresnel_closed_forms():
    n = 1.458
    rs, rp = fresnel_rs_rp(0.0, n)
    assert rs == pytest.approx(((n - 1) / (n + 1)) ** 2) and rp == pytest.approx(rs)
    assert fresnel_rs_rp(math.atan(n), n)[1] == pytest.approx(0.0, abs=1e-15)  # Brewster
    g = CoverGlass(0.5, n, 3.0)
    R = ((n - 1) / (n + 1)) ** 2
    assert g.ghost_ratio(0.0) == pytest.approx(R**2)
    assert g.direct(0.0) == pytest.approx((1 - R) ** 2)
    c = CoverGlass(0.5, n, 3.0, coating_reflectance=0.005)
    assert c.ghost_ratio(0.7) == pytest.approx(0.005**2)


def _trace(d, t, n, z_glass, f):
    """Exact vector trace of a ray from the pinhole (origin, +z towards the detector at z = f)
    through a window [z_glass, z_glass + t]: the direct ray's and the ghost's (reflected at the
    inner then the outer surface) points on the detector."""
    d = np.asarray(d, float) / np.linalg.norm(d)
    nz = np.array([0.0, 0.0, 1.0])

    def refract(v, eta):  # v unit, normal +z along the travel, eta = n1/n2
        c = v @ nz
        k = 1 - eta**2 * (1 - c * c)
        return eta * v + (math.sqrt(k) - eta * c) * nz * np.sign(c)

    p = d * (z_glass / d[2])
    v = refract(d, 1 / n)
    q = p + v * (t / v[2])  # inner surface
    out = refract(v, n)
    direct = q + out * ((f - q[2]) / out[2])
    r = v * np.array([1, 1, -1])  # back up
    q2 = q + r * (t / abs(r[2]))  # outer surface
    r2 = r * np.array([1, 1, -1])  # down again
    q3 = q2 + r2 * (t / r2[2])
    ghost = q3 + out * ((f - q3[2]) / out[2])
    return direct[:2], ghost[:2]


@pytest.mark.parametrize("deg", [0.5, 10.0, 35.0, 60.0])
def test_ghost_offset_against_a_ray_trace(deg):
    """The ghost lies 2 t tan θ′ beyond the direct spot, along the ray's azimuth, wherever the
    window sits between the pinhole and the detector."""
    th = math.radians(deg)
    d = np.array([math.sin(th) * 0.6, math.sin(th) * 0.8, math.cos(th)])
    g = CoverGlass(0.5, 1.458, 3.0)
    for z in (0.5, 1.7, 2.5):
        direct, ghost = _trace(d, 0.5, 1.458, z, 3.0)
        assert np.allclose(ghost - direct, g.offset_mm(th) * d[:2] / np.hypot(*d[:2]), atol=1e-12)
    pitch = 3.0 / 272.7
    assert np.allclose(g.offset_px(d, 272.7, 272.7), g.offset_mm(th) * d[:2] / np.hypot(*d[:2]) / pitch, atol=1e-9)


def test_glass_spots_quadrature():
    """The ghost's flux and centroid by quadrature: its flux ratio is the closed form at the sun's
    angle (to the spread of θ over the disk), its centroid the direct one plus the offset."""
    cam = PinholeBrown(fx=272.7, fy=272.8, cx=515.3, cy=508.7, k1=-0.021, k2=0.0012)
    g = CoverGlass(0.5, 1.458, 3.0)
    th = math.radians(25.0)
    s = np.array([math.sin(th), 0.0, math.cos(th)])
    t = glass_spots(cam, g, s, A, n=100_000)
    assert t["ghost_flux"] / t["direct_flux"] == pytest.approx(g.ghost_ratio(th), rel=1e-4)
    assert np.allclose(np.subtract(t["ghost_uv"], t["direct_uv"]), g.offset_px(s, cam.fx, cam.fy), atol=2e-3)


def test_effects_tables_in_the_scenes_are_off_and_checked():
    for name in ("sun_sensor_2axis_diaphragm", "sun_sensor_3axis_autocollimator"):
        rig = load_rig(name)
        for eff in ("limb_darkening", "simulator_nonuniformity", "cover_glass_ghost", "vignetting",
                    "pinhole_diffraction"):
            assert eff in rig.effects.names() and not getattr(rig.effects, eff).enabled
    data = load_rig("sun_sensor_2axis_diaphragm").model_dump(mode="json")
    data["effects"]["limb_darkening"]["u"] = 1.5
    with pytest.raises(Exception, match="u"):
        parse_rig(data)
    data["effects"]["limb_darkening"]["u"] = 0.6
    data["effects"]["simulator_nonuniformity"]["kind"] = "diagonal"
    with pytest.raises(Exception, match="kind"):
        parse_rig(data)


def test_thick_pinhole_throughput_is_the_overlap_of_two_circles():
    """V(θ) against the overlap of the entrance and exit circles counted on a grid (a second
    method), V(0) = 1, V = 0 once t tan θ ≥ D; d ln V/dθ against a finite difference."""
    from rigsim.optics.pinhole import ThickPinhole

    ph = ThickPinhole(0.1, 0.025)
    g = (np.arange(2000) + 0.5) / 2000 * 0.1 - 0.05
    X, Y = np.meshgrid(g, g)
    inside = X**2 + Y**2 < 0.05**2
    for deg in (0.0, 20.0, 45.0, 60.0, 75.0):
        c = 0.025 * math.tan(math.radians(deg))
        grid = np.sum(inside & ((X - c) ** 2 + Y**2 < 0.05**2)) / np.sum(inside)
        assert float(ph.throughput(math.radians(deg))) == pytest.approx(grid, abs=2e-3)
    assert ph.throughput(0.0) == 1.0 and ph.throughput(math.atan(4.0)) == 0.0
    th, h = math.radians(50.0), 1e-6
    fd = (math.log(ph.throughput(th + h)) - math.log(ph.throughput(th - h))) / (2 * h)
    assert ph.dlnv_dtheta(th) == pytest.approx(fd, rel=1e-6)


def test_vignetting_shift_closed_form():
    """The vignetted disk's centroid moves towards the axis by f sec²θ · (d ln V/dθ) (a/2)²/4 (the
    second moment of a uniform disk along one axis), through an undistorted pinhole."""
    from rigsim.optics.pinhole import ThickPinhole

    ph = ThickPinhole(0.1, 0.025)
    cam = PinholeBrown(fx=272.7, fy=272.7, cx=515.3, cy=508.7)
    for deg in (30.0, 50.0, 58.0):
        th = math.radians(deg)
        s = np.array([math.sin(th) * 0.8, math.sin(th) * 0.6, math.cos(th)])
        a = spot_truth(cam, s, A, n=1_000_000)
        b = spot_truth(cam, s, A, n=1_000_000, direction_weight=ph.direction_weight)
        exp = cam.fx / math.cos(th) ** 2 * ph.dlnv_dtheta(th) * (A / 2) ** 2 / 4 * np.array([0.8, 0.6])
        assert np.allclose(np.subtract(b["mean_uv"], a["mean_uv"]), exp, rtol=0.03, atol=2e-5)
        assert b["relative_flux"] / a["relative_flux"] == pytest.approx(ph.throughput(th), rel=1e-4)
