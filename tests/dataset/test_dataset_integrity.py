"""A dataset folder cannot be silently corrupted: one run owns it at a time, resume trusts no file it cannot
check, verify checks the whole plan and stays inside the folder, and nothing is written through a link."""

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from file_chain import derived_rig, rigsim_in_process

from rigsim.dataset.ownership import OWNER_FILE, dataset_lock
from rigsim.dataset.runner import generate, verify
from rigsim.errors import DatasetError

pytestmark = pytest.mark.render
RIG = "sun_sensor_2axis_diaphragm"
N = 4
SPP = 4


def _gen(root, seed=5, **kw):
    return generate(RIG, root, frames=N, seed=seed, spp=SPP, workers=1, progress=False, **kw)


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    root = tmp_path_factory.mktemp("base")
    _gen(root)
    return root


def _copy(base, tmp_path) -> Path:
    d = tmp_path / "ds"
    shutil.copytree(base, d)
    return d


def _files(root) -> dict:
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(Path(root).rglob("*")) if p.is_file()}


def test_a_second_run_on_a_held_folder_is_refused_naming_the_holder(base, tmp_path):
    d = _copy(base, tmp_path)
    before = _files(d)
    with dataset_lock(d, "test holder"):
        with pytest.raises(DatasetError, match=rf"in use by another run \(pid {os.getpid()} on .*test holder"):
            _gen(d, seed=6)
    assert not (d / OWNER_FILE).exists()
    assert _files(d) == {k: v for k, v in before.items()}  # nothing touched


def test_two_processes_on_one_folder_one_refused_the_other_whole(tmp_path):
    d = tmp_path / "ds"
    cmd = [sys.executable, "-m", "rigsim.cli", "dataset", "generate", RIG, "--out", str(d), "--frames", "6",
           "--spp", str(SPP), "--workers", "1", "--seed"]
    a = subprocess.Popen(cmd + ["1"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    t0 = time.time()
    while not (d / OWNER_FILE).exists() and a.poll() is None and time.time() - t0 < 120:
        time.sleep(0.02)
    b = subprocess.run(cmd + ["2"], capture_output=True, text=True, timeout=300)
    _, a_err = a.communicate(timeout=600)
    assert a.returncode == 0, a_err
    assert b.returncode == 2 and "in use by another run" in b.stderr and "Traceback" not in b.stderr
    assert len(b.stderr.strip().splitlines()) == 1, b.stderr
    assert verify(d) == []
    seeds = {json.loads(p.read_text())["dataset"]["params_sha256"] for p in (d / "frames").glob("*.json")}
    assert len(seeds) == 6  # six frames of one plan: the refused run wrote nothing
    assert json.loads((d / "plan.json").read_text())["seed"] == 1


def test_a_hand_edited_sidecar_is_found_and_rendered_again(base, tmp_path):
    d = _copy(base, tmp_path)
    jp = d / "frames" / "frame_000001.json"
    original = jp.read_bytes()
    sc = json.loads(original)
    sc["dataset"]["truth_row"]["spot_u"] += 5.0
    jp.write_text(json.dumps(sc, indent=1) + "\n")
    problems = verify(d)
    assert "frames/frame_000001.json: checksum mismatch (corrupt or modified)" in problems
    assert "frames/frame_000001.json: edited after it was written (its own checksum does not match)" in problems
    r = _gen(d)
    assert r.n_rendered == 1 and r.n_resumed == N - 1
    assert jp.read_bytes() == original and verify(d) == []


def test_a_sidecar_from_another_plan_is_rendered_again(base, tmp_path):
    d = _copy(base, tmp_path)
    other = tmp_path / "other"
    generate(RIG, other, frames=3, seed=99, spp=SPP, workers=1, progress=False)  # up to its frame 2
    for suffix in ("png", "json"):  # a whole, intact frame 2 of another dataset
        shutil.copy(other / "frames" / f"frame_000002.{suffix}", d / "frames" / f"frame_000002.{suffix}")
    assert "frames/frame_000002.json: written for another plan (pose, seed or options differ)" in verify(d)
    r = _gen(d)
    assert r.n_rendered == 1 and verify(d) == []
    assert _files(d)["frames/frame_000002.png"] == _files(base)["frames/frame_000002.png"]


def test_info_and_verify_print_what_the_folder_holds(base, capsys):
    """The two read-only commands on a known dataset: four PNG frames of seed 5 from this rig, every truth
    column of a frame's sidecar listed, and a whole folder."""
    from rigsim.cli import main

    assert main(["dataset", "info", str(base)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith(f"{base}: {N} PNG frames, generator ") and out[0].endswith(", seed 5")
    assert RIG in out[0]
    row = json.loads((base / "frames" / "frame_000000.json").read_text())["dataset"]["truth_row"]
    assert out[1].startswith("truth columns: ") and set(row) <= set(out[1].removeprefix("truth columns: ").split(", "))
    assert main(["dataset", "verify", str(base)]) == 0
    assert capsys.readouterr().out.strip() == f"{base}: every file matches the manifest"


def test_an_image_changed_after_its_sidecar_was_written_is_rendered_again(base, tmp_path):
    """A whole, readable PNG whose pixels differ from those its sidecar's checksum names (a frame overwritten
    after its sidecar, or a kill between a re-render's image and its sidecar): resume hashes the image and
    renders the frame again."""
    from rigsim.dataset.store import decode_image, encode_image

    d = _copy(base, tmp_path)
    ip = d / "frames" / "frame_000002.png"
    original = ip.read_bytes()
    img = decode_image(ip)
    img[0, 0] ^= 1
    ip.write_bytes(encode_image(img, "png"))
    assert "frames/frame_000002.png: checksum mismatch (corrupt or modified)" in verify(d)
    r = _gen(d)
    assert r.n_rendered == 1 and r.n_resumed == N - 1
    assert ip.read_bytes() == original and verify(d) == []


@pytest.mark.parametrize("manifest,expect", [
    ({}, "manifest.json: format = None"),
    ([], "manifest.json: a JSON object expected, found list"),
    ("x", "manifest.json: a JSON object expected, found str"),
])
def test_verify_refuses_a_manifest_of_the_wrong_shape(base, tmp_path, manifest, expect):
    d = _copy(base, tmp_path)
    (d / "manifest.json").write_text(json.dumps(manifest))
    assert any(p.startswith(expect) for p in verify(d)), verify(d)


def test_verify_checks_the_plan_not_only_the_listed_files(base, tmp_path):
    d = _copy(base, tmp_path)
    man = json.loads((d / "manifest.json").read_text())
    for i in range(2):  # two frames deleted and dropped from the manifest
        for s in ("png", "json"):
            (d / "frames" / f"frame_00000{i}.{s}").unlink()
            del man["files_sha256"][f"frames/frame_00000{i}.{s}"]
    man["files_sha256"]["../../etc/hostname"] = "0" * 64
    (d / "manifest.json").write_text(json.dumps(man))
    (d / "frames" / "notes.txt").write_text("x")
    p = verify(d)
    assert "frames/frame_000000.png: planned but not in the manifest" in p
    assert "frames/frame_000001.json: planned but not in the manifest" in p
    assert "../../etc/hostname: path leaves the dataset folder (not read)" in p
    assert "frames/notes.txt: extra file (not in the manifest)" in p


def test_links_planted_in_the_folder_are_never_written_through(base, tmp_path):
    d = _copy(base, tmp_path)
    victim = tmp_path / "victim.txt"
    victim.write_text("keep me")
    target = d / "frames" / "frame_000003.png"
    target.unlink()
    target.symlink_to(victim)
    (d / "frames" / ".frame_000000.png.abcd1234.tmp").symlink_to(victim)  # a planted 'temporary'
    (d / "frames" / ".frame_000001.json.tmp-1234").write_text("stale")
    r = _gen(d)
    assert r.n_rendered == 1 and victim.read_text() == "keep me"
    assert not target.is_symlink() and verify(d) == []
    assert not [p for p in (d / "frames").iterdir() if p.name.startswith(".")]  # stale temporaries removed
    shutil.rmtree(d / "frames")
    (d / "frames").symlink_to(tmp_path)
    with pytest.raises(DatasetError, match="frames: is a symbolic link"):
        _gen(d)
    assert not list(tmp_path.glob("frame_*"))


def _children(pid: int) -> set[int]:
    out = set()
    for p in Path("/proc").iterdir():
        if p.name.isdigit():
            try:
                stat = (p / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                out.add(int(p.name))
    return out


def _cmdline(pid: int) -> str:
    try:
        return (Path("/proc") / str(pid) / "cmdline").read_text(errors="replace")
    except OSError:
        return ""


def _alive(pid: int) -> bool:
    try:
        return (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="needs /proc (Linux)")
def test_workers_die_with_a_killed_main_process(tmp_path):
    import signal

    d = tmp_path / "ds"
    cmd = [sys.executable, "-m", "rigsim.cli", "dataset", "generate", RIG, "--out", str(d), "--frames", "200",
           "--spp", "64", "--workers", "2", "--seed", "3"]
    main = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    t0 = time.time()
    while time.time() - t0 < 120 and not (d / "frames").is_dir() or not list((d / "frames").glob("*.json")):
        if time.time() - t0 > 120:
            break
        time.sleep(0.05)
    # spawned workers are the run's children; forked by a forkserver (rigsim.render.workers), the server's
    servers = {c for c in _children(main.pid) if "forkserver" in _cmdline(c)}
    workers = {w for w in _children(main.pid) if "spawn_main" in _cmdline(w)}
    workers |= {w for s in servers for w in _children(s)}
    assert len(workers) == 2, workers
    os.kill(main.pid, signal.SIGKILL)  # the main process only, not its group
    main.wait()
    t1 = time.time()
    while any(_alive(w) for w in workers | servers) and time.time() - t1 < 10:
        time.sleep(0.05)
    assert not any(_alive(w) for w in workers | servers), "workers outlived their main process"
    n = len(list((d / "frames").glob("*.json")))
    time.sleep(1.0)
    assert len(list((d / "frames").glob("*.json"))) == n  # nothing written after the kill


COARSE_AIMING = {  # the aiming camera with 1/16 of the pixels over the same field (as the file chain's)
    r"resolution_px = \[1600, 1200\]": "resolution_px = [400, 300]", r"pixel_pitch_um = 15\.0": "pixel_pitch_um = 60.0"}
SLOW = pytest.mark.slow  # in the slow stage: the kinds rendered without a light tracer's float atomics, and one more
KINDS = [  # (rig, generator, renderer, spp): every generator, each renderer of star-field
    pytest.param("sun_sensor_2axis_diaphragm", "sun-sensor", None, 16, marks=SLOW),
    # the coarse camera (COARSE_AIMING), the same light tracer: its pencil chunks are compared between one and two
    # processes by default in tests/procedures/cube_mirror/test_concentricity.py
    pytest.param("sun_sensor_2axis_diaphragm", "aiming-camera", None, 1, marks=SLOW),
    ("sun_sensor_3axis_autocollimator", "autocollimator", None, 4),
    pytest.param("star_sensor", "star-field", "analytic", None, marks=SLOW),
    pytest.param("star_sensor", "star-field", "mitsuba", 16, marks=SLOW),
    # the boresight ROIs' light tracer: the same LoopRenderer frames are compared bit for bit between one and two
    # processes by default in tests/procedures/boresight/test_frame_pool.py
    pytest.param("dual_line_array_prism", "boresight-roi", None, 64, marks=SLOW),
]


@pytest.mark.parametrize("rig,kind,renderer,spp", KINDS,
                         ids=[f"{k}-{r or ''}" for _, k, r, _ in (getattr(x, "values", x) for x in KINDS)])
def test_the_same_seed_gives_byte_identical_frames_for_one_or_two_workers(tmp_path, rig, kind, renderer, spp):
    """Light tracers splat with float atomics whose order depends on the thread count; a single worker
    renders with every thread, two workers with one each: the frames must not differ by a single DN. The
    aiming camera's frames are rendered on a coarse camera (the same field and light tracer, 1/16 of the pixels);
    the commands read the frames in this process (their subprocess runs: the file chain,
    tests/procedures/cube_mirror/test_file_chain.py)."""
    if kind == "aiming-camera":
        rig = str(derived_rig(rig, tmp_path / "coarse_aiming.toml", COARSE_AIMING))
    shas = []
    for w in (1, 2):
        r = generate(rig, tmp_path / f"w{w}", frames=2, seed=7, generator=kind, renderer=renderer, spp=spp, workers=w,
                     progress=False, chunk=1)
        shas.append({k: v for k, v in r.manifest["files_sha256"].items() if k.endswith((".png", ".fits"))})
    assert len(shas[0]) >= 2 and shas[0] == shas[1]
    # the file chain: the commands that read these kinds read a dataset's frames (docs/formats.md)
    frames = sorted(str(p) for p in (tmp_path / "w1" / "frames").glob("*.png"))
    if kind == "aiming-camera":  # frame 0 the lit hole, frame 1 the returned spot
        rigsim_in_process("concentricity", frames[0], frames[1], "--rig", rig, "--json", tmp_path / "c.json")
        assert np.all(np.isfinite(json.loads((tmp_path / "c.json").read_text())["offset_px"]))
    elif kind == "autocollimator":
        rigsim_in_process("autocollimator", "read", frames[0], "--rig", rig, "--json", tmp_path / "a.json")
        assert np.all(np.isfinite(json.loads((tmp_path / "a.json").read_text())["reading_arcsec"]))


def test_workers_choose_the_tested_libllvm_whatever_drjit_libllvm_path_says(tmp_path):
    """A user's DRJIT_LIBLLVM_PATH naming a library that fails the self-test (here a file that is no libLLVM at
    all, standing in for libLLVM 15/16, which abort the interpreter) must not reach drjit in any process: every
    worker renders with the llvm variant and the frames match a single worker's byte for byte."""
    from rigsim.render.backend import loaded_libllvm  # noqa: F401  (the module must import without drjit)

    bad = tmp_path / "lib" / "libLLVM-15.so.1"
    bad.parent.mkdir()
    bad.write_bytes(b"\x7fELF not a library")
    env = {**os.environ, "DRJIT_LIBLLVM_PATH": str(bad), "RIGSIM_CACHE_DIR": str(tmp_path / "cache")}
    env.pop("RIGSIM_VARIANT", None)
    shas = []
    for w in (1, 2):
        out = tmp_path / f"w{w}"
        cmd = [sys.executable, "-m", "rigsim", "dataset", "generate", RIG, "--out", str(out), "--frames", "2",
               "--spp", "16", "--workers", str(w), "--seed", "7"]
        r = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
        assert r.returncode == 0, r.stderr[-2000:]
        variants = {json.loads(p.read_text())["render"].get("variant") for p in (out / "frames").glob("*.json")}
        assert variants == {"llvm_ad_mono"}, (variants, r.stderr[-2000:])
        m = json.loads((out / "manifest.json").read_text())
        shas.append({k: v for k, v in m["files_sha256"].items() if k.endswith(".png")})
    assert len(shas[0]) == 2 and shas[0] == shas[1]
