"""The concentricity fit's room-light option (``hole_spot_offset(..., background="plane")``) on exact
rasters of the hole and the spot: a lit screen with a gradient defeats the default hole threshold;
the plane background recovers the offset, whether the hole glows above the lit screen or shows dark."""

import numpy as np
import pytest

from rigsim.imaging.screen import border_plane, hole_spot_offset
from rigsim.optics.screen_surface import ambient_illuminance
from rigsim.rig import load_rig
from rigsim.truth.cube_mirror.diaphragm import diaphragm_geometry, rasterise_screen_disk
from rigsim.truth.cube_mirror.realization import realization_from_rig

RIG = load_rig("sun_sensor_2axis_diaphragm")
RIG = RIG.model_copy(update={"aiming_camera": RIG.aiming_camera.model_copy(update={"resolution_px": [768, 576]})})
G = diaphragm_geometry(RIG, realization_from_rig(RIG), 0)
OPX = RIG.aiming_camera.object_pixel_mm
OFFSET = np.array([3.0, -1.0])  # spot − hole, mm (a spot clear of the hole)


def _frames(pedestal: float):
    """Hole frame (glow 1000 DN) and spot frame (+ a 2 mm spot of 1000 DN), a lit screen of ``pedestal``
    DN at the hole rising 20 % per 100 mm towards +X' (absent inside the hole), dark offset 100 DN."""
    W, H = G.camera.width, G.camera.height
    uu, vv = np.meshgrid(np.arange(W, dtype=float), np.arange(H, dtype=float))
    st = G.uv_to_screen(np.stack([uu, vv], -1).reshape(-1, 2)).reshape(H, W, 2)
    hole = rasterise_screen_disk(G, (0.0, 0.0), G.hole_radius_mm)
    spot = rasterise_screen_disk(G, OFFSET, 1.0)
    lit = ambient_illuminance(st, pedestal, 0.2, 0.0) * (1.0 - hole)
    return 100.0 + 1000.0 * hole + lit, 100.0 + 1000.0 * hole + lit + 1000.0 * spot


def _offset(pedestal, background):
    h, s = _frames(pedestal)
    m = hole_spot_offset(h, s, G, object_pixel_mm=OPX, offset_dn=100.0, background=background)
    return m["offset_mm"], m


def test_border_plane_recovers_a_smooth_background():
    H, W = 100, 140
    U, V = np.meshgrid(np.arange(W, dtype=float), np.arange(H, dtype=float))
    img = 5.0 + 0.1 * U - 0.03 * V + 1e-4 * U * V
    img[30:70, 40:100] += 1000.0  # the middle holds the light: ignored
    assert np.allclose(border_plane(img), 5.0 + 0.1 * U - 0.03 * V + 1e-4 * U * V, atol=1e-9)


@pytest.mark.parametrize("pedestal", [0.0, 100.0])
def test_dim_room_light_both_fits_agree(pedestal):
    for bg in ("none", "plane"):
        off, _ = _offset(pedestal, bg)
        assert np.linalg.norm(off - OFFSET) / OPX < 0.05, (bg, off)


@pytest.mark.parametrize("pedestal", [600.0, 2500.0])
def test_lit_screen_breaks_the_default_fit_and_not_the_plane_background(pedestal):
    """600 DN (the hole glows 1.7× the screen) and 2500 DN (the hole is a dark disk on the lit screen)."""
    off, _ = _offset(pedestal, "none")
    assert np.linalg.norm(off - OFFSET) / OPX > 5.0  # the default's threshold takes the lit screen
    off, m = _offset(pedestal, "plane")
    print(pedestal, "plane:", (off - OFFSET) / OPX, "px", m["hole_pixels"], "hole pixels")
    assert np.linalg.norm(off - OFFSET) / OPX < 0.05


def test_unknown_background_is_refused():
    h, s = _frames(0.0)
    with pytest.raises(ValueError, match="background"):
        hole_spot_offset(h, s, G, object_pixel_mm=OPX, offset_dn=100.0, background="median")
