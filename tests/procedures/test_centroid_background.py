"""``rigsim centroid`` on frames that a rig's detector model does not describe: it says so, and
``--background frame`` measures the background on the frame instead."""

import numpy as np
import pytest

from rigsim.cli import main
from rigsim.files import write_image

SPOT = (541.3, 477.8)


def read_table(path) -> dict[str, list[float]]:
    import csv

    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    return {k: [float(r[k]) for r in rows] for k in ("u_px", "v_px")}


def _frame(pedestal: float, noise_dn: float, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    v, u = np.mgrid[0:1024, 0:1024]
    img = pedestal + noise_dn * rng.standard_normal((1024, 1024))
    img += 4000.0 * np.exp(-((u - SPOT[0]) ** 2 + (v - SPOT[1]) ** 2) / (2 * 2.5**2))
    return np.clip(np.round(img), 0, 4095).astype(np.uint16)


@pytest.mark.parametrize("pedestal, noise, said", [(64.0, 3.0, "the detector model expects 1.00 DN"),
                                                   (100.0, 3.0, "36.0 DN above the detector's offset")])
def test_a_frame_the_model_does_not_describe_is_named_and_measured_on_its_own_background(
        tmp_path, capsys, pedestal, noise, said):
    f = tmp_path / "hand.png"
    write_image(f, _frame(pedestal, noise))
    rig = ["--rig", "sun_sensor_2axis_diaphragm", "--quiet"]
    assert main(["centroid", str(f), "--out", str(tmp_path / "model.csv"), *rig]) == 0
    err = capsys.readouterr().err
    assert "warning: " + str(f) in err and said in err and "--background frame" in err
    m = read_table(tmp_path / "model.csv")  # noise peaks by the thousand, or the whole frame as one spot
    assert not (len(m["u_px"]) == 1 and abs(m["u_px"][0] - SPOT[0]) < 0.01)

    assert main(["centroid", str(f), "--out", str(tmp_path / "frame.csv"), "--background", "frame", *rig]) == 0
    assert "warning" not in capsys.readouterr().err
    t = read_table(tmp_path / "frame.csv")
    assert len(t["u_px"]) == 1
    # a σ = 2.5 px Gaussian with ~157 000 DN and 3 DN noise: the S-curve centroid is within 0.01 px
    assert abs(t["u_px"][0] - SPOT[0]) < 0.01 and abs(t["v_px"][0] - SPOT[1]) < 0.01


def test_the_rigs_own_frame_raises_no_warning(tmp_path, capsys):
    from rigsim.render.cube_mirror.sun_sensor import SunSensorScene
    from rigsim.rig.load import load_any_rig

    rig = load_any_rig("sun_sensor_2axis_diaphragm")
    fr = SunSensorScene(rig, spp=16).render({"X": 0.2, "Y": -0.1}, seed=3, truth_points=2000)
    f = tmp_path / "sun.png"
    write_image(f, fr.dn)
    assert main(["centroid", str(f), "--out", str(tmp_path / "s.csv"), "--rig", "sun_sensor_2axis_diaphragm",
                 "--quiet"]) == 0
    assert "warning" not in capsys.readouterr().err
    assert len(read_table(tmp_path / "s.csv")["u_px"]) == 1


def test_background_frame_refuses_a_given_offset(tmp_path, capsys):
    f = tmp_path / "hand.png"
    write_image(f, _frame(64.0, 1.0))
    assert main(["centroid", str(f), "--out", str(tmp_path / "x.csv"), "--background", "frame",
                 "--offset-dn", "64"]) == 2
    assert "leave out --offset-dn" in capsys.readouterr().err
    assert not (tmp_path / "x.csv").exists()
