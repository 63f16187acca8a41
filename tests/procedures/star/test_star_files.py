"""Seed 004 on a user's files: the frames of the rendered campaign, copied out as bare renamed
files with the commanded attitudes as a CSV, give the in-process batch (f, u0, v0, k1, k2) and
every EKF state to 1e-9 relative through `rigsim star calibrate`; bad logs and frames are one line."""

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from file_chain import rigsim, rigsim_in_process

from rigsim.cli import main
from rigsim.files import Column, read_table, write_table


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """The campaign in-process, its frames exported as FITS (the default) with the attitude log."""
    d = tmp_path_factory.mktemp("star")
    assert main(["run", "star-calibration", "--no-study", "--export-frames", str(d / "frames"),
                 "--out", str(d / "report"), "--quiet"]) == 0
    return d


def _scale_qw(path, frame, factor):
    lines = path.read_text().splitlines()
    for i, ln in enumerate(lines):
        if ln.startswith(frame + ","):
            f = ln.split(",")
            f[2] = repr(float(f[2]) * factor)
            lines[i] = ",".join(f)
    path.write_text("\n".join(lines) + "\n")


def _replace(fits_path, png_bytes):
    """A PNG in place of a FITS frame (the same stem; the log names the .png)."""
    fits_path.unlink()
    fits_path.with_suffix(".png").write_bytes(png_bytes)
    log = fits_path.parent / "log.csv"
    log.write_text(log.read_text().replace(fits_path.name + ",", fits_path.with_suffix(".png").name + ","))


def _bare(exported, dst):
    """Renamed copies (reverse order, new names) and the log rewritten: no sidecars, no truth."""
    dst.mkdir()
    cols = [Column("frame", kind="str"), Column("time", "s"), Column("qw"), Column("qx"), Column("qy"), Column("qz")]
    t = read_table(exported / "frames" / "attitudes.csv", cols)
    names = {f: f"shot-{k:02d}.fits" for k, f in enumerate(reversed(list(t["frame"])))}
    for f, g in names.items():
        shutil.copy(exported / "frames" / f, dst / g)
    out = {k: v for k, v in t.items() if k != "__line__"}
    out["frame"] = [names[f] for f in out["frame"]]
    write_table(dst / "log.csv", out)
    return dst


def test_frames_round_trip_through_star_calibrate(exported, tmp_path):
    """The exported FITS frames, renamed, through `star calibrate` in a subprocess, as a lab runs it: the
    in-process batch θ and every EKF state to 1e-9; the result validates against the packaged schema."""
    import jsonschema

    d = _bare(exported, tmp_path / "bare")
    rigsim("star", "calibrate", *sorted(p.name for p in d.glob("shot-*")), "--attitudes", "log.csv", "--out", "cal",
           "--opencv", "cal/camera.yml", cwd=d)
    got = json.loads((d / "cal" / "calibration.json").read_text())
    jsonschema.validate(got, _star_schema())
    assert got["mode"] == "files" and got["true_theta"] is None and got["batch"]["error"] is None
    assert len(got["attitudes"]) == 20 and all(x["identified"] for x in got["attitudes"])
    # the joint calibration in OpenCV's form: read back by cv2.FileStorage (through rig import-camera's reader)
    from rigsim.rig.opencv_camera import read_opencv_camera

    cv = read_opencv_camera(d / "cal" / "camera.yml")
    th = dict(zip(got["theta_names"], got["joint"]["theta"]))
    assert (cv.fx, cv.fy, cv.cx, cv.cy, cv.dist["k1"], cv.dist["k2"]) == (th["f"], th["f"], th["u0"], th["v0"], th["k1"], th["k2"])
    assert cv.size == (1024, 1024)
    ref = json.loads((exported / "report" / "star_calibration.json").read_text())
    b, rb = np.array(got["batch"]["theta"]), np.array(ref["batch"]["theta"])
    assert np.all(np.abs(b - rb) <= 1e-9 * np.abs(rb))
    assert set(got["ekf"]) == {"f_nominal/ad", "f_nominal/ads", "f_joint/ad", "f_joint/ads"}
    for k, e in got["ekf"].items():
        r = np.array(ref["ekf"][k]["theta"])
        assert np.all(np.abs(np.array(e["theta"]) - r) <= 1e-9 * np.abs(r)), k
        assert np.allclose(e["covariance"]["sigma"], ref["ekf"][k]["covariance"]["sigma"], rtol=1e-9)
    # the covariance block is the batch's inverse normal matrix: its σ are the report's
    assert np.allclose(got["batch"]["covariance"]["sigma"], ref["batch"]["covariance"]["sigma"], rtol=1e-9)
    stars = read_table(d / "cal" / "stars.csv", [Column("frame", kind="str"), Column("u", "px"), Column("identified", kind="int")])
    assert stars["identified"].sum() == got["identification"]["identified"] > 1900
    # the camera it wrote is read by `rig import-camera` (in this process: the cube-mirror file chain runs it as a
    # subprocess)
    rigsim_in_process("rig", "import-camera", "cal/camera.yml", "--rig", "star_sensor", "--out", "imported.toml", cwd=d)
    assert "focal_length_mm" in (d / "imported.toml").read_text()


@pytest.mark.parametrize("edit, message", [
    (lambda d: (d / "log.csv").write_text((d / "log.csv").read_text().replace("time_s", "time_ms")),
     r"log\.csv: column time_ms: expected time_s \(seconds\), got milliseconds"),
    (lambda d: (d / "log.csv").write_text((d / "log.csv").read_text().replace("shot-03.fits,", "shot-03.fits,x")),
     r"log\.csv: line \d+, column time_s: 'x[\d.]+' is not a number"),
    (lambda d: _scale_qw(d / "log.csv", "shot-01.fits", 1.01),
     r"log\.csv: line \d+, columns qw\.\.qz: \|q\| = [\d.]+; expected a unit quaternion"),
    (lambda d: _replace(d / "shot-02.fits", cv2.imencode(".png", np.zeros((1024, 1024, 3), np.uint8))[1].tobytes()),
     r"shot-02\.png: 3-channel \(colour\) image; expected a single-channel grey star frame"),
    (lambda d: _replace(d / "shot-02.fits", cv2.imencode(".png", np.zeros((512, 1024), np.uint16))[1].tobytes()),
     r"shot-02\.png: 1024×512 px \(width×height\); expected 1024×1024 px, the rig's detector"),
    (lambda d: (d / "log.csv").write_text("\n".join(ln for ln in (d / "log.csv").read_text().splitlines()
                                                    if not ln.startswith("shot-04"))),
     r"shot-04\.fits: frame 'shot-04\.fits' has no row in the attitude log"),
])
def test_bad_inputs_one_line(exported, tmp_path, capsys, edit, message):
    import re

    d = _bare(exported, tmp_path / "bare")
    edit(d)
    rc = main(["star", "calibrate", *sorted(str(p) for p in d.glob("shot-*")), "--attitudes", str(d / "log.csv"),
               "--out", str(d / "cal")])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1 and re.search(message, err), err
    assert not (d / "cal").exists()


def _rewrite_log(path, fn):
    t = read_table(path, [Column("frame", kind="str"), Column("time", "s"), Column("qw"), Column("qx"), Column("qy"),
                          Column("qz")])
    q = np.column_stack([t["qw"], t["qx"], t["qy"], t["qz"]])
    q = fn(q)
    write_table(path, {"frame": list(t["frame"]), "time_s": t["time_s"], "qw": q[:, 0], "qx": q[:, 1], "qy": q[:, 2],
                       "qz": q[:, 3]})


@pytest.mark.parametrize("fn, named", [
    (lambda q: q[:, [1, 2, 3, 0]], "read scalar last, they agree with the stars"),        # (x, y, z, w) under qw..qz
    (lambda q: q * [1, -1, -1, -1], "read conjugated, they agree with the stars"),        # R(ICRS←cam)
    (lambda q: (q * [1, -1, -1, -1])[:, [1, 2, 3, 0]], "read scalar last and conjugated"),
    (lambda q: np.roll(q, 7, axis=0), "is the log for these frames"),                     # another frame's attitude
])
def test_a_log_in_another_quaternion_convention_is_named(exported, tmp_path, capsys, fn, named):
    """The two commonest mistakes in an attitude log: the scalar written last, and the inverse rotation. Frames
    identified without a prior tell which one it is; when none of the first three frames identifies from the log,
    that is said before the other frames are read. Nothing is written."""
    d = _bare(exported, tmp_path / "bare")
    _rewrite_log(d / "log.csv", fn)
    rc = main(["star", "calibrate", *sorted(str(p) for p in d.glob("shot-*")), "--attitudes", str(d / "log.csv"),
               "--out", str(d / "cal")])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1 and named in err, err
    if named.startswith(("read scalar last,", "read conjugated")):  # none of the first three frames identifies
        assert "0 of the first 3 frames identify" in err, err
    assert not (d / "cal").exists()


def test_a_frame_listed_twice_or_two_frames_of_one_name_are_refused(exported, tmp_path, capsys):
    d = _bare(exported, tmp_path / "bare")
    frames = sorted(str(p) for p in d.glob("shot-*"))
    (d / "again").mkdir()
    shutil.copy(frames[3], d / "again" / "shot-03.fits")
    for extra, words in (([frames[2]], "the same file as"), ([str(d / "." / Path(frames[2]).name)], "the same file as"),
                         ([str(d / "again" / "shot-03.fits")], "two star frames named 'shot-03.fits'")):
        rc = main(["star", "calibrate", *frames, *extra, "--attitudes", str(d / "log.csv"), "--out", str(d / "cal")])
        err = capsys.readouterr().err.strip()
        assert rc == 2 and len(err.splitlines()) == 1 and words in err, err
    assert not (d / "cal").exists()


def _star_schema():
    from importlib.resources import files

    return json.loads(files("rigsim").joinpath("schemas/star-calibration.schema.json").read_text())


def test_the_run_star_json_has_the_published_shape_with_its_truth(exported):
    """star_calibration.json (rigsim's run: the truth and the error beside each estimate) validates against the
    schema shipped in the package (a user's calibration.json: test_frames_round_trip_through_star_calibrate);
    the run's errors are the estimates minus the true θ and each attitude's error is small_angle_error(R, R_true)."""
    import jsonschema

    from rigsim.frames import ARCSEC_PER_RAD, small_angle_error

    ref = json.loads((exported / "report" / "star_calibration.json").read_text())
    schema = _star_schema()
    jsonschema.validate(ref, schema)
    assert ref["mode"] == "analytic" and ref["seed"] == 0
    t = np.array(ref["true_theta"])
    np.testing.assert_allclose(ref["batch"]["error"], np.array(ref["batch"]["theta"]) - t, atol=1e-12)
    for e in ref["ekf"].values():
        np.testing.assert_allclose(e["error"], np.array(e["theta"]) - t, atol=1e-12)
    a = [x["R_cam_from_icrs"] for x in ref["attitudes"] if x["identified"]]
    assert len(a) == 20
    for x in a:
        want = small_angle_error(np.array(x["matrix"]), np.array(x["true_matrix"])) * ARCSEC_PER_RAD
        np.testing.assert_allclose(x["error_arcsec"], want, atol=1e-9)
    # the calibrated attitudes' errors match their covariance (centroid noise + the batch θ's); the identification's
    # nominal-camera attitudes are off by the nominal principal point's error (~200″ about x and y), far outside theirs
    # Every frame shares the batch θ's one error, so per axis the 20 values are one common draw plus per-frame
    # centroid noise: the common part is a single normal draw (|z| < 3.29 at 99.9 %); the scatter about it is
    # the centroid part of σ, at most the whole σ (1 + 3 × 0.16, the spread of a 20-sample standard deviation).
    chi = np.array([np.array(x["error_arcsec"]) / x["covariance"]["sigma"] for x in a])
    common = chi.mean(axis=0)
    scatter = (chi - common).std(axis=0, ddof=1)
    assert np.all(np.abs(common) < 3.29), chi
    assert np.all(scatter < 1.5), scatter
    nom = np.array([np.abs(x["R_cam_from_icrs_nominal"]["error_arcsec"]) / x["R_cam_from_icrs_nominal"]["covariance"]["sigma"]
                    for x in ref["attitudes"]])
    assert np.median(nom[:, :2]) > 100
    with pytest.raises(jsonschema.ValidationError):  # a run result without its truth is not a valid run result
        jsonschema.validate({**ref, "true_theta": None}, schema)


def test_attitude_covariance_matches_a_monte_carlo_of_wahba_fits():
    """[Σ (I − b bᵀ)/σ²]⁻¹ against the scatter of 4000 SVD attitude fits (scipy align_vectors) to noisy unit
    vectors in a 10° field: each axis's σ within 5 % (the Monte-Carlo's own error is ~1.1 %)."""
    from scipy.spatial.transform import Rotation

    from rigsim.procedures.star.files import attitude_covariance_rad2

    rng = np.random.default_rng(7)
    n = 12
    xy = rng.uniform(-0.09, 0.09, (n, 2))
    b = np.column_stack([xy, np.ones(n)])
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    sig = rng.uniform(1.0, 3.0, n) * 1e-5
    P = attitude_covariance_rad2(b, sig)
    errs = []
    for _ in range(4000):
        dn = rng.normal(0.0, 1.0, (n, 3)) * sig[:, None]
        dn -= np.sum(dn * b, axis=1, keepdims=True) * b  # σ per axis across the line of sight
        noisy = b + dn
        noisy /= np.linalg.norm(noisy, axis=1, keepdims=True)
        R, _ = Rotation.align_vectors(noisy, b, weights=1.0 / sig**2)
        errs.append(R.as_rotvec())
    emp = np.cov(np.array(errs).T)
    np.testing.assert_allclose(np.sqrt(np.diag(emp)), np.sqrt(np.diag(P)), rtol=0.05)


def test_lost_in_space_needs_no_attitude(exported, tmp_path, capsys):
    """With no attitude in the log (frame, time_s only), lost-in-space identification finds the same
    stars in every frame: the same calibration as with the commanded prior."""
    d = _bare(exported, tmp_path / "bare")
    t = read_table(d / "log.csv", [Column("frame", kind="str"), Column("time", "s")])
    write_table(d / "times.csv", {"frame": list(t["frame"]), "time_s": t["time_s"]})
    frames = sorted(str(p) for p in d.glob("shot-*"))
    assert main(["star", "calibrate", *frames, "--attitudes", str(d / "times.csv"), "--identify", "lost-in-space",
                 "--out", str(d / "lis")]) == 0
    got = json.loads((d / "lis" / "calibration.json").read_text())
    ref = json.loads((exported / "report" / "star_calibration.json").read_text())
    assert got["identification"]["frames_identified"] == 20
    assert np.allclose(got["batch"]["theta"], ref["batch"]["theta"], rtol=1e-9, atol=0)
    assert main(["star", "calibrate", *frames, "--attitudes", str(d / "times.csv"), "--out", str(d / "x")]) == 2
    assert "times.csv: no column qw" in capsys.readouterr().err


def test_the_report_explains_the_diverged_improved_ads(exported):
    """The patent's improved ADS (eq 12) ends far off (its approximation drops a term as large as the one it keeps):
    the report says so in one line beside the number, so that a reader does not take it for a bug."""
    md = (exported / "report" / "report.md").read_text()
    assert "improved ADS (the patent's eq 12) ends up to" in md and "not a bug" in md


def test_exported_fits_frames_carry_the_known_wcs(exported):
    """run star-calibration --export-frames (FITS): every frame's header holds a TAN-SIP WCS built from what the
    spacecraft knows (the commanded attitude in attitudes.csv, the nominal camera), never the truth: astropy's
    world_to_pixel of sky directions across the field lands within 0.01 px of the nominal camera's projection
    (astropy's pixel API is 0-based like rigsim's; FITS's CRPIX is 1-based), with the exposure keywords."""
    from astropy.coordinates import SkyCoord
    from astropy.io import fits
    from astropy.wcs import WCS
    from scipy.spatial.transform import Rotation

    from rigsim.rig.load import load_star_rig

    d = exported / "frames"
    rig = load_star_rig()
    cam = rig.nominal_rig().sensor.camera()
    log = read_table(d / "attitudes.csv", [Column("frame", kind="str"), Column("qw"), Column("qx"), Column("qy"), Column("qz")])
    rng = np.random.default_rng(5)
    for k in (0, 7, 19):
        with fits.open(d / log["frame"][k]) as hd:
            h = hd[0].header
            assert hd[0].data.shape == (1024, 1024)
        assert h["CTYPE1"] == "RA---TAN-SIP" and h["WCSNAME"].startswith("commanded attitude")
        assert h["EXPTIME"] == rig.sensor.detector.exposure_s and h["BUNIT"] == "adu" and "T" in h["DATE-OBS"]
        q = [log[c][k] for c in ("qx", "qy", "qz", "qw")]
        R = Rotation.from_quat(q).as_matrix()  # R(cam←ICRS), scalar-first in the file
        uv_want = rng.uniform(20, 1004, (50, 2))
        dirs_cam = cam.unproject(uv_want)
        dirs = dirs_cam @ R
        sc = SkyCoord(x=dirs[:, 0], y=dirs[:, 1], z=dirs[:, 2], representation_type="cartesian", frame="icrs")
        px, py = WCS(h).world_to_pixel(sc)
        err = np.hypot(px - uv_want[:, 0], py - uv_want[:, 1])
        assert err.max() < 0.01, err.max()
