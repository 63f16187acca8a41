"""Target layouts, bitmaps, poses and exact projection (rigsim.optics.targets), against OpenCV."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from rigsim.errors import InputError
from rigsim.optics.camera import PinholeBrown
from rigsim.optics.targets import chessboard, parse_target, project_target, read_poses, spread_poses, write_poses

CAM = PinholeBrown(420.0, 421.0, 243.2, 176.9, -0.12, 0.035, 6e-4, -4e-4, 0.002, width=480, height=360)


def test_chessboard_layout_and_bitmap():
    t = parse_target("chessboard:10x7:20")
    assert t.pattern_size == (9, 6) and t.points_mm.shape == (54, 2)
    assert np.allclose(t.points_mm[:3], [[0, 0], [20, 0], [40, 0]]) and np.allclose(t.points_mm[9], [0, 20])
    bm = t.bitmap()
    assert bm.shape == (9, 12)  # rows + 2 margin, cols + 2 margin: one texel per square
    x0, y0, x1, y1 = t.extent_mm
    assert (x1 - x0, y1 - y0) == (12 * 20, 9 * 20)
    assert bm[0].min() == 1 and bm[:, 0].min() == 1 and bm[-1].min() == 1 and bm[:, -1].min() == 1  # white margin
    assert bm[1, 1] == 0 and bm[1, 2] == 1 and bm[2, 1] == 1  # top-left square black, alternating
    # texel (1, 1) spans x, y in [-20, 0): point 0 is its bottom-right corner
    assert x0 + 1 * 20 == -20 and x0 + 2 * 20 == 0
    assert bm[1:-1, 1:-1].mean() == pytest.approx(0.5, abs=1 / (2 * 70))


def test_circle_bitmap_disk_area_and_centre():
    t = parse_target("circles:4x3:20:10")
    assert t.pattern_size == (4, 3) and np.allclose(t.points_mm[5], [20, 20])
    bm = t.bitmap()
    n = t.params["texels_per_pitch"]
    assert bm.shape == (4 * n, 5 * n)
    dark = 1.0 - bm
    # each disk covers π r² (sampling error of the 4×4 supersampled edge ~ 1e-3)
    cell = dark[n // 2 + n: n // 2 + 2 * n, n // 2 + n: n // 2 + 2 * n]  # the disk at point (1, 1)... centred cell
    assert cell.sum() / n**2 == pytest.approx(np.pi * 0.25**2, rel=2e-3)
    # its centroid is the disk centre, a texel corner at (2n, 2n) in texel units (centres at k + 0.5)
    v, u = np.indices(cell.shape)
    cu = (cell * (u + 0.5)).sum() / cell.sum() + n // 2 + n
    cv = (cell * (v + 0.5)).sum() / cell.sum() + n // 2 + n
    assert (cu, cv) == (pytest.approx(2 * n, abs=1e-9), pytest.approx(2 * n, abs=1e-9))


def test_image_target_corners_and_levels(tmp_path):
    img = np.full((30, 40), 200, np.uint8)
    img[:15, :20] = 0
    cv2.imwrite(str(tmp_path / "logo.png"), img)
    t = parse_target(f"image:{tmp_path / 'logo.png'}:80")
    assert np.allclose(t.points_mm, [[0, 0], [80, 0], [80, 60], [0, 60]])
    assert t.bitmap()[0, 0] == 0 and t.bitmap()[-1, -1] == pytest.approx(200 / 255)
    img16 = np.full((10, 10), 65535, np.uint16)
    cv2.imwrite(str(tmp_path / "w16.png"), img16)
    assert parse_target(f"image:{tmp_path / 'w16.png'}:10").bitmap().max() == 1.0
    cv2.imwrite(str(tmp_path / "rgb.png"), np.zeros((8, 8, 3), np.uint8))
    with pytest.raises(InputError, match=r"rgb\.png: 3-channel"):
        parse_target(f"image:{tmp_path / 'rgb.png'}:10")


@pytest.mark.parametrize("spec, match", [
    ("chessboard:10:20", "is not COLSxROWS"), ("chessboard:10x7", "expected chessboard:COLSxROWS:SQUARE_MM"),
    ("chessboard:10x7:-5", "square -5.0 mm"), ("chessboard:2x7:20", "3 to 200 squares"),
    ("circles:7x5:20:25", "below the pitch"), ("circles:7x5:20", "PITCH_MM:DIAM_MM"),
    ("hexagons:3x3:1", "unknown kind 'hexagons'"), ("image:nothing.png:x", "WIDTH_MM 'x' is not a number"),
])
def test_bad_specs_one_line(spec, match):
    with pytest.raises(InputError, match=match) as e:
        parse_target(spec)
    assert "\n" not in str(e.value)


def test_projection_equals_cv2_and_visibility():
    t = chessboard(8, 6, 10.0)
    rv, tv = np.array([12.0, -20.0, 7.0]), np.array([-30.0, -20.0, 220.0])
    uv, vis = project_target(CAM, t.points_mm, rv, tv)
    ref, _ = cv2.projectPoints(t.object_points(), np.radians(rv), tv, CAM.camera_matrix(), CAM.dist_coeffs())
    assert np.abs(uv - ref.reshape(-1, 2)).max() < 1e-9
    assert vis.all()
    # slid sideways: the points past the detector's right edge are not visible, the others are
    uv2, vis2 = project_target(CAM, t.points_mm, rv, tv + [130.0, 0, 0])
    assert 0 < vis2.sum() < len(vis2) and np.array_equal(vis2, CAM.on_detector(uv2))
    # turned round (printed side away from the camera) at the same place: nothing visible
    _, vis3 = project_target(CAM, t.points_mm, [0.0, 180.0, 0.0], [30.0, -20.0, 220.0])
    assert not vis3.any()


def test_poses_round_trip_and_errors(tmp_path):
    t = chessboard(8, 6, 10.0)
    p = spread_poses(t, 5, distance_mm=(200.0, 240.0), field_deg=15.0, seed=2)
    for suffix in (".csv", ".parquet"):
        q = read_poses(write_poses(tmp_path / f"p{suffix}", p), t)
        assert q.frames == p.frames and np.array_equal(q.rvec_deg, p.rvec_deg) and np.array_equal(q.tvec_mm, p.tvec_mm)
    # every spread pose shows the whole board within the field asked for
    for k in range(5):
        assert project_target(CAM, t.points_mm, p.rvec_deg[k], p.tvec_mm[k])[1].all()
    head = "frame,rx_deg,ry_deg,rz_deg,tx_mm,ty_mm,tz_mm\n"
    bad = {
        "frame,rx_rad,ry_deg,rz_deg,tx_mm,ty_mm,tz_mm\na,0,0,0,0,0,300\n": r"column rx_rad: expected rx_deg \(degrees\)",
        head + "a,0,0,0,0,0,300\na,0,0,0,0,0,300\n": r"line 3, column frame: 'a' already used on line 2",
        head + "a/b,0,0,0,0,0,300\n": r"line 2, column frame: 'a/b'; expected a file stem",
        head + "a,0,0,0,0,0,-300\n": r"line 2: the target's centre is at z = -300 mm",
        head + "a,0,x,0,0,0,300\n": r"line 2, column ry_deg: 'x' is not a number",
        head: "no rows",
    }
    for k, (text, match) in enumerate(bad.items()):
        f = tmp_path / f"bad{k}.csv"
        f.write_text(text)
        with pytest.raises(InputError, match=match) as e:
            read_poses(f, t)
        assert str(e.value).startswith(str(f)) and "\n" not in str(e.value)
