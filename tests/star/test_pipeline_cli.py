"""End to end on rendered frames (6 frames) and the CLI's input errors."""

import numpy as np

from rigsim.cli import main
from rigsim.procedures.star.pipeline import run_pipeline


def test_pipeline_end_to_end(rig):
    small = rig.model_copy(update={"sequence": rig.sequence.model_copy(update={"n_frames": 6})})
    r = run_pipeline(small, seed=3)
    ist, cs = r.ident_stats, r.centroid_stats
    assert ist["frames_identified"] == 6 and ist["wrong"] == 0 and ist["identified"] > 0.95 * ist["usable"]
    # Gaussian-fit centroids reach the CRLB (docs/imaging.md: 0.99–1.01); 1000+ stars → ±3 % sampling
    assert 0.9 < cs["error_over_crlb_rms"] < 1.12
    assert all(0.9 < c < 1.12 for c in cs["chi_rms"])
    # calibration vs truth within 4σ of its own covariance
    b = r.batch
    assert np.all(np.abs(b.theta - r.truth_theta) < 4 * b.sigma), (b.theta - r.truth_theta) / b.sigma
    e = r.ekf[("f_known", "ad")]
    assert np.all(np.abs(e.x - r.truth_theta[1:3]) < 4 * e.sigma)
    # with f biased by 3 px the principal point is off by far more than its σ (the study's point)
    e = r.ekf[("f_biased", "ad")]
    assert np.max(np.abs(e.x - r.truth_theta[1:3])) > 10 * np.max(e.sigma)


def test_cli_errors(capsys, tmp_path):
    assert main(["run", "star-calibration", "--renderer", "povray", "--quiet"]) == 2
    assert "--renderer = 'povray'" in capsys.readouterr().err
    assert main(["run", "star-calibration", "--trials", "1", "--quiet"]) == 2
    assert "2 to 100000" in capsys.readouterr().err
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "x"\n[sensor]\nfocal_length_mm = 0.5\n')
    assert main(["run", "star-calibration", "--rig", str(bad), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "bad.toml" in err and "sensor.focal_length_mm" in err and "0.5" in err and "> 1.0" in err
