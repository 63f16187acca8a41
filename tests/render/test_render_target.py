"""A planar target through a rig's true camera (rigsim.render.target, `rigsim render target`), checked
with OpenCV: detected chessboard corners and circle centres against the exact projections, and
cv2.calibrateCamera recovering the true intrinsics within their standard deviations."""

from __future__ import annotations

import argparse
import time

import cv2
import numpy as np
import pytest

from rigsim.detector.config import DetectorConfig
from rigsim.errors import RigsimError
from rigsim.files import Column, read_json, read_table
from rigsim.optics.camera import PinholeBrown
from rigsim.optics.targets import parse_target, project_target, spread_poses, write_poses

pytest.importorskip("mitsuba")

# a small camera with moderate distortion (≈ 17 px per 10-mm square at 220 mm)
CAM = PinholeBrown(420.0, 421.0, 243.2, 176.9, -0.12, 0.035, 6e-4, -4e-4, 0.0, width=480, height=360)
DET = DetectorConfig(quantum_efficiency=0.6, full_well_e=20000.0, read_noise_e=5.0, gain_dn_per_e=0.2, adc_bits=12,
                     sensor_seed=5)
NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")


def _corners(dn, pattern, win):
    im = dn.astype(np.float32)
    im8 = np.round((im - im.min()) / (im.max() - im.min()) * 255).astype(np.uint8)
    for flags in (cv2.CALIB_CB_ADAPTIVE_THRESH, cv2.CALIB_CB_ADAPTIVE_THRESH + cv2.CALIB_CB_NORMALIZE_IMAGE):
        ok, c = cv2.findChessboardCorners(im8, pattern, flags=flags)
        if ok:
            break
    else:
        return None
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-5)
    return cv2.cornerSubPix(im, c, (win, win), (-1, -1), crit).reshape(-1, 2)


def _match(found, exact):
    """Index of the exact point nearest each detected one (a permutation, each within 1 px)."""
    d = np.linalg.norm(found[:, None] - exact[None], axis=-1)
    j = d.argmin(1)
    assert len(set(j.tolist())) == len(j) and d.min(1).max() < 1.0
    return j


def _calibrate(views, cam):
    """cv2.calibrateCamera from (object points, detected) pairs: estimate, σ, reprojection rms."""
    obj = [o.astype(np.float32) for o, _ in views]
    img = [i.astype(np.float32) for _, i in views]
    rms, K, dist, *_rest, sd, _sde, _pve = cv2.calibrateCameraExtended(
        obj, img, (cam.width, cam.height), cam.camera_matrix(), np.zeros(5), flags=cv2.CALIB_USE_INTRINSIC_GUESS)
    est = np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2], *dist.ravel()[:5]])
    return est, sd.ravel()[:9], rms


def _pixel(dn, uv):
    return float(dn[round(uv[1]), round(uv[0])])


def test_chessboard_corners_and_calibrate_camera():
    from rigsim.render.target import TargetScene

    t = parse_target("chessboard:8x6:10")
    poses = spread_poses(t, 16, distance_mm=(200.0, 240.0), field_deg=15.0, tilt_deg=25.0, seed=7)
    scene = TargetScene(CAM, t, DET, spp=16)
    views, res = [], []
    for k in range(len(poses)):
        fr = scene.render(poses.rvec_deg[k], poses.tvec_mm[k], seed=k)
        p = fr.truth["points"]
        exact = np.column_stack([p["u_px"], p["v_px"]])
        assert all(p["visible"])
        if k == 0:  # upright, unmirrored: square (0, 0) (centre at (-5, -5) mm) dark, its right neighbour white
            sq, _ = project_target(CAM, np.array([[-5.0, -5.0], [5.0, -5.0]]), poses.rvec_deg[0], poses.tvec_mm[0])
            assert _pixel(fr.dn, sq[0]) < 0.2 * _pixel(fr.dn, sq[1])
        found = _corners(fr.dn, t.pattern_size, 4)
        assert found is not None, f"pose {k}: no chessboard found"
        j = _match(found, exact)
        res.append(found - exact[j])
        views.append((t.object_points()[j], found))
    res = np.concatenate(res)
    rms = float(np.sqrt((res**2).sum(1).mean()))
    # measured 0.086 px rms (cornerSubPix's own bias on 17-px squares under distortion; noise-free 256 spp: same)
    assert rms < 0.15 and np.abs(res.mean(0)).max() < 0.03
    est, sd, reproj = _calibrate(views, CAM)
    z = (est - CAM.params()) / sd
    assert np.all(np.abs(z) < 3.0), dict(zip(NAMES, z.round(2)))
    assert reproj < 0.15


def _raycast(cam, target, scene, rv, tv, box, n=16):
    """Expected photons of a crop by numpy alone: n×n sub-pixel rays unprojected through the camera model,
    intersected with the board plane, the square looked up, weighted by the flux fall-off."""
    from rigsim.optics.targets import target_to_camera

    u0, u1, v0, v1 = box
    R, t = target_to_camera(rv, tv)
    bm = target.bitmap()
    x0, y0, x1, y1 = target.extent_mm
    H, W = bm.shape
    L = scene.white_photons * (scene.black_reflectance + (1 - scene.black_reflectance) * bm)
    U, V = np.meshgrid(np.arange(u0, u1), np.arange(v0, v1))
    acc = np.zeros(U.shape)
    for a in (np.arange(n) + 0.5) / n - 0.5:
        for b in (np.arange(n) + 0.5) / n - 0.5:
            uv = np.stack([U + a, V + b], -1).reshape(-1, 2)
            d, _ = cam.backproject(uv)
            q = ((R[:, 2] @ t) / (d @ R[:, 2]))[:, None] * d - t
            q = q @ R
            i = np.floor((q[:, 0] - x0) / (x1 - x0) * W).astype(int)
            j = np.floor((q[:, 1] - y0) / (y1 - y0) * H).astype(int)
            inside = (i >= 0) & (i < W) & (j >= 0) & (j < H)
            acc += (np.where(inside, L[j.clip(0, H - 1), i.clip(0, W - 1)], 0.0) * cam.flux_weight(uv)).reshape(U.shape)
    return acc / n**2


def test_photons_equal_numpy_raycast():
    """The rendered (pre-detector) image of a tilted board equals an independent numpy ray cast to Monte-Carlo
    noise: measured 0.24 % of white rms over an 80×80 crop with 8 corners (a 0.02-px shift of the ray cast: 0.47 %)."""
    from rigsim.render.target import TargetScene

    t = parse_target("chessboard:8x6:10")
    rv, tv = np.array([15.0, -20.0, 5.0]), np.array([-10.0, -20.0, 220.0])
    scene = TargetScene(CAM, t, DET, spp=256)
    fr = scene.render(rv, tv, seed=1, noiseless=True)
    box = (200, 280, 140, 220)
    d = (fr.photons[box[2]:box[3], box[0]:box[1]] - _raycast(CAM, t, scene, rv, tv, box)) / scene.white_photons
    assert np.sqrt((d**2).mean()) < 0.0035 and abs(d.mean()) < 2e-4


def test_same_seed_same_frame_and_points_off_detector():
    from rigsim.render.target import TargetScene

    t = parse_target("chessboard:4x3:10")
    scene = TargetScene(CAM, t, DET, spp=4)
    a = scene.render([0, 0, 0], [105.0, 0.0, 200.0], seed=3)
    b = scene.render([0, 0, 0], [105.0, 0.0, 200.0], seed=3)
    assert np.array_equal(a.dn, b.dn)
    vis = np.array(a.truth["points"]["visible"])
    u = np.array(a.truth["points"]["u_px"])
    assert np.array_equal(vis, u < CAM.width - 0.5) and 0 < vis.sum() < len(vis)
    assert a.flags["points_not_visible"] == int((~vis).sum())


def test_circle_grid_centres():
    from rigsim.render.target import TargetScene

    t = parse_target("circles:6x4:12:6")
    poses = spread_poses(t, 3, distance_mm=(200.0, 230.0), field_deg=12.0, seed=1)
    scene = TargetScene(CAM, t, DET, spp=16)
    res = []
    for k in range(3):
        fr = scene.render(poses.rvec_deg[k], poses.tvec_mm[k], seed=k)
        im8 = np.round((fr.dn - fr.dn.min()) / np.ptp(fr.dn) * 255).astype(np.uint8)
        ok, c = cv2.findCirclesGrid(im8, t.pattern_size, flags=cv2.CALIB_CB_SYMMETRIC_GRID)
        assert ok
        exact = np.column_stack([fr.truth["points"]["u_px"], fr.truth["points"]["v_px"]])
        c = c.reshape(-1, 2)
        res.append(c - exact[_match(c, exact)])
    rms = float(np.sqrt((np.concatenate(res) ** 2).sum(1).mean()))
    # the blob centre is the image's centroid, not the projected centre: a perspective bias of a few 0.01 px
    assert rms < 0.06


def test_image_target_corners(tmp_path):
    from rigsim.render.target import TargetScene

    img = np.full((30, 40), 255, np.uint8)
    img[:15, :20] = 0  # dark top-left quadrant
    cv2.imwrite(str(tmp_path / "logo.png"), img)
    t = parse_target(f"image:{tmp_path / 'logo.png'}:80")
    cam = PinholeBrown(800.0, 800.0, 239.5, 179.5, width=480, height=360)  # no distortion: straight edges
    scene = TargetScene(cam, t, DET, spp=64, black_reflectance=0.0)
    rv, tv = [0.0, 0.0, 0.0], [-40.3, -30.2, 250.0]
    fr = scene.render(rv, tv, seed=0, noiseless=True)
    ph = fr.photons
    corners = np.column_stack([fr.truth["points"]["u_px"], fr.truth["points"]["v_px"]])
    row = ph[round(corners[2, 1]) - 10]  # a row through the white lower half
    lit = np.flatnonzero(row > 0.02 * row.max())
    a, b = int(lit.min()), int(lit.max())
    # the end pixels of the lit run are partly covered: their fraction of the neighbour's (cos⁴ fall-off) gives the edge
    u_left = a + 0.5 - row[a] / row[a + 1]
    u_right = b - 0.5 + row[b] / row[b - 1]
    assert u_left == pytest.approx(corners[0, 0], abs=0.02) and u_right == pytest.approx(corners[1, 0], abs=0.02)
    tl = project_target(cam, np.array([[20.0, 15.0], [60.0, 45.0]]), rv, tv)[0]
    assert _pixel(ph, tl[0]) < 0.01 * _pixel(ph, tl[1])


def _run(argv) -> int:
    """`rigsim render ARGV` through the command's own parser, printing errors as rigsim's main does."""
    from rigsim.procedures import target_commands

    p = argparse.ArgumentParser(prog="rigsim")
    rds = p.add_subparsers().add_parser("render").add_subparsers()
    target_commands.add_cli({"render": rds})
    args = p.parse_args(["render", *argv])
    try:
        return args.func(args)
    except RigsimError as exc:
        import sys

        print(f"rigsim: error: {exc}", file=sys.stderr)
        return 2


def test_command_writes_frames_points_and_truth(tmp_path, capsys):
    t = parse_target("chessboard:10x7:20")
    poses = spread_poses(t, 2, distance_mm=(260.0, 300.0), field_deg=30.0, seed=4, prefix="board")
    write_poses(tmp_path / "poses.csv", poses)
    out = tmp_path / "out"
    t0 = time.perf_counter()
    rc = _run(["target", "--target", "chessboard:10x7:20", "--poses", str(tmp_path / "poses.csv"), "--out", str(out),
               "--quiet"])
    assert rc == 0 and time.perf_counter() - t0 < 20
    assert "54 points" in capsys.readouterr().out
    tab = read_table(out / "points.csv", [Column("frame", kind="str"), Column("point", kind="int"), Column("x", "mm"),
                                          Column("y", "mm"), Column("u", "px"), Column("v", "px"),
                                          Column("visible", kind="int")])
    info = read_json(out / "target.json", required=("camera_true", "pattern_size"))
    cam = PinholeBrown(**info["camera_true"])
    assert info["pattern_size"] == [9, 6] and cam.fx == pytest.approx(3.0 / 0.011)
    for k, name in enumerate(poses.frames):
        png = out / f"{name}.png"
        dn = cv2.imread(str(png), cv2.IMREAD_UNCHANGED)
        assert dn.dtype == np.uint16 and dn.shape == (1024, 1024)
        side = read_json(out / f"{name}.json", required=("truth",))
        sel = tab["frame"] == png.name
        uv = np.column_stack([tab["u_px"][sel], tab["v_px"][sel]])
        ref, _ = cv2.projectPoints(t.object_points(), np.radians(poses.rvec_deg[k]), poses.tvec_mm[k],
                                   cam.camera_matrix(), cam.dist_coeffs())
        assert np.abs(uv - ref.reshape(-1, 2)).max() < 1e-9
        assert np.array_equal(uv[:, 0], side["truth"]["points"]["u_px"]) and tab["visible"][sel].all()
        found = _corners(dn, (9, 6), 5)
        assert found is not None
        assert np.sqrt(((found - uv[_match(found, uv)]) ** 2).sum(1).mean()) < 0.15


def test_command_errors_one_line(tmp_path, capsys):
    good = "frame,rx_deg,ry_deg,rz_deg,tx_mm,ty_mm,tz_mm\na,0,0,0,0,0,300\n"
    bad = "frame,rx_deg,ry_deg,rz_deg,tx_mm,ty_mm,tz_m\na,0,0,0,0,0,0.3\n"
    cases = [
        (bad, ["--target", "chessboard:10x7:20"], "p.csv: column tz_m: expected tz_mm (millimetres), got metres"),
        (good, ["--target", "chessboard:10x7"], "expected chessboard:COLSxROWS:SQUARE_MM"),
        (good, ["--target", "chessboard:10x7:20", "--camera", "autocollimator"], "(focused at infinity"),
        (good, ["--target", "chessboard:10x7:20", "--spp", "10"], "--spp = 10: expected a power of 4"),
        (good, ["--target", "chessboard:10x7:20", "--rig", "dual_line_array_prism"], "no area camera"),
    ]
    for text, extra, msg in cases:
        (tmp_path / "p.csv").write_text(text)
        assert _run(["target", *extra, "--poses", str(tmp_path / "p.csv"), "--out", str(tmp_path / "o"), "--quiet"]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("rigsim: error:") and "\n" not in err and msg in err, err
        assert not (tmp_path / "o" / "a.png").exists()


@pytest.mark.slow
def test_default_sun_sensor_calibrates_within_3_sigma(tmp_path):
    """The default rig's sun sensor (f ≈ 273 px, ±60°, 1024²): 16 chessboard poses through the command's
    function, corners against points.csv, calibrateCamera against the true intrinsics."""
    from rigsim.optics.targets import read_poses
    from rigsim.procedures.target_commands import render_target_frames
    from rigsim.rig.load import load_rig

    rig = load_rig()
    t = parse_target("chessboard:10x7:20")
    write_poses(tmp_path / "poses.csv", spread_poses(t, 16, distance_mm=(230.0, 300.0), field_deg=45.0, seed=3))
    s = render_target_frames(rig, t, read_poses(tmp_path / "poses.csv", t), tmp_path / "out", spp=16)
    tab = read_table(s["points"], [Column("frame", kind="str"), Column("u", "px"), Column("v", "px")])
    cam = rig.sun_sensor.camera()
    views, res = [], []
    for png in s["frames"]:
        sel = tab["frame"] == png.name
        uv = np.column_stack([tab["u_px"][sel], tab["v_px"][sel]])
        found = _corners(cv2.imread(str(png), cv2.IMREAD_UNCHANGED), t.pattern_size, 5)
        assert found is not None, png.name
        j = _match(found, uv)
        res.append(found - uv[j])
        views.append((t.object_points()[j], found))
    rms = float(np.sqrt((np.concatenate(res) ** 2).sum(1).mean()))
    assert rms < 0.12  # measured 0.079 px
    est, sd, _ = _calibrate(views, cam)
    z = (est - cam.params()) / sd
    assert np.all(np.abs(z) < 3.0), dict(zip(NAMES, z.round(2)))


def test_spread_poses_fill_the_field_of_each_camera():
    """--spread's poses, derived from each camera's field and focal length: at least 90 % of the target points
    land on the detector, and the boards span 25 to 70 % of its width (exact projection, no render)."""
    from rigsim.optics.targets import project_target
    from rigsim.procedures.target_commands import spread_for_camera
    from rigsim.render.target import true_camera
    from rigsim.rig.load import load_any_rig

    t = parse_target("chessboard:10x7:20")
    for rig_name, cam_name in (("sun_sensor_2axis_diaphragm", "sun-sensor"), ("sun_sensor_2axis_diaphragm", "aiming-camera"),
                               ("star_sensor", "star-sensor")):
        rig = load_any_rig(rig_name)
        _, cam, _ = true_camera(rig, cam_name)
        poses = spread_for_camera(rig, t, 24, camera=cam_name, seed=5)
        vis, span = [], []
        for k in range(len(poses)):
            uv, ok = project_target(cam, t.points_mm, poses.rvec_deg[k], poses.tvec_mm[k])
            vis.append(ok.mean())
            span.append(np.ptp(uv[ok, 0]) / cam.width if ok.any() else 0.0)
        assert np.mean(vis) > 0.9, (rig_name, cam_name, np.round(vis, 2))
        assert 0.25 < np.median(span) < 0.7, (rig_name, cam_name, np.median(span))
