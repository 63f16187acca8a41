"""Variant/libLLVM choice: subprocess self-test, cache, fallback, no mitsuba at import."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from rigsim.render import backend

SRC = str(Path(backend.__file__).resolve().parents[2])
LLVM19 = "/usr/lib/x86_64-linux-gnu/libLLVM-19.so"
LLVM15 = "/usr/lib/x86_64-linux-gnu/libLLVM-15.so"


def _run(code: str, env_extra: dict | None = None, timeout=300):
    env = dict(os.environ)
    env["PYTHONPATH"] = SRC + os.pathsep + env.get("PYTHONPATH", "")
    env.update(env_extra or {})
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], env=env,
                          capture_output=True, text=True, timeout=timeout)


def test_importing_render_modules_does_not_import_mitsuba():
    r = _run("""
        import sys
        import rigsim.render, rigsim.render.backend, rigsim.optics.camera, rigsim.render.frame
        import rigsim.render.plugins, rigsim.render.cube_mirror.sun_sensor, rigsim.detector
        print(sorted(m for m in ('mitsuba', 'drjit') if m in sys.modules))
    """)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "[]"


@pytest.mark.parametrize("name,version", [
    ("libLLVM-19.so", 19), ("libLLVM.so.19.1", 19), ("libLLVM-15.so.1", 15),
    ("libLLVM-14.0.6.so.1", 14), ("libLLVM.so", None), ("libLLVMX86CodeGen.a", None),
])
def test_version_parsing(name, version):
    assert backend._version_of(name) == version


def test_candidates_are_shared_libraries_newest_first():
    cands = backend.llvm_candidates()
    reals = [c.realpath for c in cands]
    assert len(reals) == len(set(reals))
    globbed = [c.version for c in cands if c.source == "glob"]
    assert globbed == sorted(globbed, key=lambda v: -(v or 0))
    assert all(".a" not in os.path.basename(c.path) for c in cands)
    if os.path.exists(LLVM19):
        assert os.path.realpath(LLVM19) in reals


def test_broken_library_gets_a_bad_verdict_without_killing_us(tmp_path, monkeypatch):
    monkeypatch.setenv("RIGSIM_CACHE_DIR", str(tmp_path))
    fake = tmp_path / "libLLVM-99.so"
    fake.write_bytes(b"\x7fELF this is not a library")
    cand = backend.LLVMCandidate(path=str(fake), realpath=str(fake), version=99, source="glob")
    v = backend.probe_llvm(cand)
    assert v["ok"] is False and v["cached"] is False
    # cached on disk, keyed by the file: the second call spawns no subprocess
    monkeypatch.setattr(backend, "_run_selftest", lambda *a: pytest.fail("not cached"))
    backend._state.pop("probes", None)
    v2 = backend.probe_llvm(cand)
    assert v2["ok"] is False and v2["cached"] is True
    data = json.loads((tmp_path / "llvm.json").read_text())
    assert any(str(fake) in k for k in data["verdicts"])


@pytest.mark.skipif(not os.path.exists(LLVM15), reason="libLLVM 15 not installed")
def test_libllvm15_abort_is_contained(tmp_path, monkeypatch):
    """libLLVM 15 aborts (SIGABRT) at the first dr.minimum kernel -- in the child only."""
    monkeypatch.setenv("RIGSIM_CACHE_DIR", str(tmp_path))
    backend._state.pop("probes", None)
    cand = backend.LLVMCandidate(path=LLVM15, realpath=os.path.realpath(LLVM15), version=15,
                                 source="glob")
    v = backend.probe_llvm(cand)
    assert v["ok"] is False
    assert v["returncode"] == -6 and "SIGABRT" in v["detail"]


@pytest.mark.skipif(not os.path.exists(LLVM19), reason="libLLVM 19 not installed")
def test_choose_variant_prefers_llvm_mono_here():
    assert backend.choose_variant() == "llvm_ad_mono"
    assert backend.choose_variant(spectral=True) == "llvm_ad_spectral"


def test_ensure_variant_is_idempotent_and_sets_mitsuba():
    v = backend.ensure_variant()
    assert backend.ensure_variant() == v
    import mitsuba as mi

    assert mi.variant() == v


def test_fallback_to_scalar_with_one_warning_line(tmp_path):
    """No working libLLVM -> scalar_rgb, exactly one warning line on stderr, and it renders."""
    fake = tmp_path / "libLLVM-99.so"
    fake.write_bytes(b"not a library")
    r = _run(f"""
        import sys
        from rigsim.render import backend
        bad = backend.LLVMCandidate(path={str(fake)!r}, realpath={str(fake)!r}, version=99,
                                    source="glob")
        backend.llvm_candidates = lambda: [bad]
        v = backend.ensure_variant()
        v2 = backend.ensure_variant()
        import mitsuba as mi
        import numpy as np
        from rigsim.optics.camera import PinholeBrown
        from rigsim.render.cube_mirror.sun_sensor import SunSpotRenderer
        cam = PinholeBrown(fx=100.0, fy=100.0, cx=15.5, cy=15.5, width=32, height=32)
        win = SunSpotRenderer(cam, full_angle_rad=0.05, window_px=8, spp=4).render([0, 0, 1])
        print(v, v2, mi.variant(), round(float(win.image.sum()), 3))
    """, {"RIGSIM_CACHE_DIR": str(tmp_path), "DRJIT_LIBLLVM_PATH": ""})
    assert r.returncode == 0, r.stderr
    out = r.stdout.split()
    assert out[:3] == ["scalar_rgb"] * 3
    assert float(out[3]) > 0
    warn_lines = [ln for ln in r.stderr.splitlines() if "falling back" in ln]
    assert len(warn_lines) == 1 and "scalar_rgb" in warn_lines[0]


def test_doctor_report_shape():
    rep = backend.doctor_report(test_all=False)
    for key in ("python", "mitsuba", "drjit", "llvm_candidates", "llvm_chosen", "variant",
                "fallback_variant", "notes"):
        assert key in rep
    assert rep["fallback_variant"] == "scalar_rgb"
    json.dumps(rep)
    for row in rep["llvm_candidates"]:
        assert {"path", "version", "verdict"} <= set(row)
        assert row["verdict"] in ("ok", "bad", "untested")
    if os.path.exists(LLVM19):
        assert rep["variant"] == "llvm_ad_mono"
        assert os.path.realpath(rep["llvm_chosen"]) == os.path.realpath(LLVM19)
