"""Mitsuba variant choice that cannot crash the calling process.

drjit loads libLLVM once, at ``import drjit``, from ``DRJIT_LIBLLVM_PATH`` (else ``libLLVM.so``,
else the newest ``libLLVM*.so.*`` it finds). A bad libLLVM does not raise: libLLVM 14 is refused
(the llvm backend silently disappears) and libLLVM 15/16 abort the whole interpreter with SIGABRT
at the first kernel that uses ``dr.minimum`` (drjit 1.5.0 emits ``llvm.minimum``). So before
mitsuba is imported in this process we

1. list candidate libraries (``DRJIT_LIBLLVM_PATH``; a ``libLLVM.so`` on the usual library path;
   ``/usr/lib/x86_64-linux-gnu/libLLVM*.so*`` and ``/usr/lib/llvm-*/lib/libLLVM*.so*``; newest
   version first, duplicates by real path removed),
2. self-test each in a *subprocess* (:mod:`rigsim.render._llvm_selftest`: import mitsuba, set the
   llvm variant, run a ``dr.minimum`` kernel and a tiny render) until one passes,
3. cache every verdict in ``~/.cache/rigsim/llvm.json`` (``$XDG_CACHE_HOME`` / ``$RIGSIM_CACHE_DIR``
   respected), keyed by real path + size + mtime + mitsuba/drjit versions, so a second start costs
   no subprocess,
4. set ``DRJIT_LIBLLVM_PATH`` to the winner, then import mitsuba and ``mi.set_variant``.

When no library passes, the scalar variant is used and ONE warning line is logged.

Variant choice: intensity-only rendering (everything rigsim renders today: sun spots, screens,
autocollimator reticles) uses ``llvm_ad_mono`` -- one float per sample, about 3x less work than
``llvm_ad_rgb`` and no colour bookkeeping. ``spectral=True`` gives ``llvm_ad_spectral``. The
fallback is ``scalar_rgb`` / ``scalar_spectral`` (this mitsuba wheel ships no ``scalar_mono``).
``RIGSIM_VARIANT`` overrides the choice (e.g. ``RIGSIM_VARIANT=scalar_rgb`` to exercise the fallback).

Importing this module does not import mitsuba or drjit.
"""

from __future__ import annotations

import glob
import json
import logging
import os
import platform
import re
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

__all__ = [
    "LLVMCandidate",
    "LLVM_VARIANT",
    "LLVM_SPECTRAL_VARIANT",
    "SCALAR_VARIANT",
    "SCALAR_SPECTRAL_VARIANT",
    "llvm_candidates",
    "probe_llvm",
    "choose_variant",
    "ensure_variant",
    "doctor_report",
    "loaded_libllvm",
    "cache_path",
    "release_memory",
    "trim_memory",
    "cap_mmap_threshold",
]

log = logging.getLogger("rigsim.render")

LLVM_VARIANT = "llvm_ad_mono"
LLVM_SPECTRAL_VARIANT = "llvm_ad_spectral"
SCALAR_VARIANT = "scalar_rgb"
SCALAR_SPECTRAL_VARIANT = "scalar_spectral"

_SELFTEST = Path(__file__).with_name("_llvm_selftest.py")
_SELFTEST_TIMEOUT_S = 180.0
_CACHE_FORMAT = 1
_SELFTEST_VERSION = 2  # bump when _llvm_selftest.py changes so old verdicts are re-tested

_LIB_DIRS = (
    "/usr/lib/x86_64-linux-gnu",
    "/usr/lib64",
    "/usr/lib",
    "/usr/local/lib",
    "/lib/x86_64-linux-gnu",
)
_NAME_RE = re.compile(r"^libLLVM(?:-(\d+)(?:\.[\d.]+)?)?\.so(?:\.(\d+)(?:\.[\d.]+)?)?$")

_lock = threading.Lock()
_state: dict = {  # in-process memo: chosen variant, libllvm, probe results
    "user_env_path": os.environ.get("DRJIT_LIBLLVM_PATH"),
}


@dataclass(frozen=True)
class LLVMCandidate:
    path: str          # as found (may be a symlink)
    realpath: str
    version: int | None
    source: str        # "DRJIT_LIBLLVM_PATH" | "libLLVM.so" | "glob"


def _version_of(name: str) -> int | None:
    m = _NAME_RE.match(os.path.basename(name))
    if not m:
        return None
    v = m.group(1) or m.group(2)
    return int(v) if v else None


def llvm_candidates() -> list[LLVMCandidate]:
    """Candidate libLLVM shared libraries in the order drjit would consider them.

    Order: ``$DRJIT_LIBLLVM_PATH`` (as set when this process started, or by the user), then a
    plain ``libLLVM.so`` on the library path, then versioned libraries newest first. Files that
    are not shared libraries (``.a``) or are duplicates by real path are dropped.
    """
    out: list[LLVMCandidate] = []
    seen: set[str] = set()

    def add(path: str, source: str) -> None:
        if not os.path.isfile(path):
            return
        real = os.path.realpath(path)
        if real in seen:
            return
        seen.add(real)
        ver = _version_of(path) or _version_of(real)
        out.append(LLVMCandidate(path=path, realpath=real, version=ver, source=source))

    user = _state.get("user_env_path")
    if user:
        add(user, "DRJIT_LIBLLVM_PATH")
    for d in _LIB_DIRS:
        add(os.path.join(d, "libLLVM.so"), "libLLVM.so")
    found = []
    for pattern in ("/usr/lib/x86_64-linux-gnu/libLLVM*.so*", "/usr/lib/llvm-*/lib/libLLVM*.so*",
                    "/usr/local/lib/libLLVM*.so*", "/usr/lib64/libLLVM*.so*"):
        for p in glob.glob(pattern):
            if _NAME_RE.match(os.path.basename(p)):
                found.append(p)
    # newest version first; among equals prefer the shorter (canonical) name
    found.sort(key=lambda p: (-(_version_of(p) or 0), len(p), p))
    for p in found:
        add(p, "glob")
    # a plain libLLVM.so gets its version from the real file name; keep DRJIT_LIBLLVM_PATH first
    head = [c for c in out if c.source == "DRJIT_LIBLLVM_PATH"]
    rest = [c for c in out if c.source != "DRJIT_LIBLLVM_PATH"]
    rest.sort(key=lambda c: (0 if c.source == "libLLVM.so" else 1, -(c.version or 0)))
    return head + rest


def cache_path() -> Path:
    from rigsim.files.cache import cache_dir

    return cache_dir() / "llvm.json"


def _pkg_version(name: str) -> str:
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return "missing"


def _cache_key(c: LLVMCandidate, variant: str) -> str:
    st = os.stat(c.realpath)
    return "|".join([
        c.realpath, str(st.st_size), str(st.st_mtime_ns), variant,
        "mitsuba=" + _pkg_version("mitsuba"), "drjit=" + _pkg_version("drjit"),
        "python=" + platform.python_version(), "selftest=" + str(_SELFTEST_VERSION),
    ])


def _load_cache() -> dict:
    p = cache_path()
    try:
        data = json.loads(p.read_text())
        if data.get("format") == _CACHE_FORMAT and isinstance(data.get("verdicts"), dict):
            return data
    except (OSError, ValueError):
        pass
    return {"format": _CACHE_FORMAT, "verdicts": {}}


def _store_verdict(key: str, verdict: dict) -> None:
    p = cache_path()
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        data = _load_cache()
        data["verdicts"][key] = verdict
        from rigsim.errors import InputError
        from rigsim.files.atomic import atomic_write_bytes

        try:
            atomic_write_bytes(p, json.dumps(data, indent=1, sort_keys=True).encode())  # never a torn file
        except InputError as exc:
            raise OSError(str(exc)) from None
    except OSError as exc:  # read-only home: the verdict is still memoised in-process
        log.debug("cannot write %s: %s", p, exc)


def _run_selftest(c: LLVMCandidate, variant: str) -> dict:
    env = dict(os.environ)
    env["DRJIT_LIBLLVM_PATH"] = c.path
    env.pop("RIGSIM_VARIANT", None)
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(
            [sys.executable, str(_SELFTEST), variant], env=env, capture_output=True, text=True,
            timeout=_SELFTEST_TIMEOUT_S, cwd=os.path.dirname(str(_SELFTEST)),
        )
    except subprocess.TimeoutExpired:
        return {"ok": False, "detail": f"self-test timed out after {_SELFTEST_TIMEOUT_S:.0f} s",
                "returncode": None, "seconds": round(time.perf_counter() - t0, 2)}
    dt = round(time.perf_counter() - t0, 2)
    ok = proc.returncode == 0 and "RIGSIM-SELFTEST" in proc.stdout
    if ok:
        detail = "passed (dr.minimum kernel + 8x8 render)"
    elif proc.returncode < 0:
        import signal

        try:
            sig = signal.Signals(-proc.returncode).name
        except ValueError:
            sig = f"signal {-proc.returncode}"
        last = _last_line(proc.stderr)
        detail = f"crashed with {sig}" + (f": {last}" if last else "")
    else:
        detail = f"failed (exit {proc.returncode})" + (
            f": {_last_line(proc.stderr)}" if proc.stderr.strip() else "")
    return {"ok": ok, "detail": detail, "returncode": proc.returncode, "seconds": dt}


def _last_line(text: str) -> str:
    """The most telling line of a child's stderr: an 'LLVM ERROR' line if any, else the last."""
    lines = [ln.strip() for ln in (text or "").splitlines() if ln.strip()]
    for ln in lines:
        if "LLVM ERROR" in ln:
            return ln[:200]
    return lines[-1][:200] if lines else ""


def probe_llvm(candidate: LLVMCandidate, variant: str = LLVM_VARIANT, *,
               use_cache: bool = True) -> dict:
    """Verdict for one library: ``{"ok", "detail", "returncode", "seconds", "cached"}``.

    Runs the self-test in a subprocess unless a cached verdict for the same file (size, mtime)
    and the same mitsuba/drjit/python versions exists.
    """
    key = _cache_key(candidate, variant)
    memo = _state.setdefault("probes", {})
    if use_cache and key in memo:
        return memo[key]
    if use_cache:
        cached = _load_cache()["verdicts"].get(key)
        if cached is not None:
            v = dict(cached, cached=True)
            memo[key] = v
            return v
    v = _run_selftest(candidate, variant)
    v["tested_at"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
    _store_verdict(key, v)
    v = dict(v, cached=False)
    memo[key] = v
    return v


def _mitsuba_variants() -> list[str] | None:
    """Variants compiled into the installed mitsuba wheel, without importing mitsuba."""
    try:
        import importlib.util

        spec = importlib.util.find_spec("mitsuba")
    except (ImportError, ValueError):
        return None
    if spec is None or not spec.submodule_search_locations:
        return None
    root = Path(list(spec.submodule_search_locations)[0])
    names = sorted({m.group(1) for p in root.iterdir()
                    if (m := re.match(r"^((?:scalar|llvm|cuda)_[a-z_]+?)\.(?:cpython|abi3|so)", p.name))})
    return names or None


def _llvm_variant(spectral: bool) -> str:
    return LLVM_SPECTRAL_VARIANT if spectral else LLVM_VARIANT


def _scalar_variant(spectral: bool) -> str:
    return SCALAR_SPECTRAL_VARIANT if spectral else SCALAR_VARIANT


def _pick_library(spectral: bool) -> tuple[LLVMCandidate | None, list[tuple[LLVMCandidate, dict]]]:
    variant = _llvm_variant(spectral)
    tried = []
    for c in llvm_candidates():
        v = probe_llvm(c, variant)
        tried.append((c, v))
        if v["ok"]:
            return c, tried
    return None, tried


def choose_variant(spectral: bool = False) -> str:
    """The Mitsuba variant this process should use (without setting it).

    ``llvm_ad_mono`` (``llvm_ad_spectral`` if ``spectral``) when a libLLVM passes the subprocess
    self-test, else ``scalar_rgb`` (``scalar_spectral``). ``$RIGSIM_VARIANT`` overrides.
    May spawn one self-test subprocess per untested candidate (cached on disk afterwards).
    """
    forced = os.environ.get("RIGSIM_VARIANT")
    if forced:
        return forced
    key = ("choice", spectral)
    with _lock:
        if key in _state:
            return _state[key][0]
        lib, _ = _pick_library(spectral)
        variant = _llvm_variant(spectral) if lib is not None else _scalar_variant(spectral)
        _state[key] = (variant, lib)
        return variant


def loaded_libllvm() -> str | None:
    """Real path of the libLLVM mapped into this process (None if none is loaded)."""
    try:
        with open("/proc/self/maps") as fh:
            for line in fh:
                if "libLLVM" in line:
                    parts = line.split()
                    if len(parts) >= 6 and ".so" in parts[-1]:
                        return os.path.realpath(parts[-1])
    except OSError:
        pass
    return None


def ensure_variant(spectral: bool = False) -> str:
    """Choose, then set, the Mitsuba variant in this process. Idempotent; returns the variant.

    Sets ``DRJIT_LIBLLVM_PATH`` to the self-tested library before drjit is first imported. If
    drjit was already imported by someone else, the library it loaded is checked instead (one that
    failed the self-test makes us use the scalar variant rather than risk a SIGABRT).
    """
    with _lock:
        done = _state.get("set")
        if done is not None and done[1] == spectral:
            return done[0]
    forced = os.environ.get("RIGSIM_VARIANT")
    variant = forced or choose_variant(spectral)
    if variant.startswith("llvm"):
        lib, _ = _pick_library(spectral)
        if lib is None:
            if forced:
                raise RuntimeError(f"RIGSIM_VARIANT={forced} but no libLLVM passed the self-test; "
                                   "see `rigsim doctor`")
        elif "drjit" not in sys.modules:
            os.environ["DRJIT_LIBLLVM_PATH"] = lib.path
        else:
            loaded = loaded_libllvm()
            if loaded != lib.realpath:
                verdict = None
                for c in llvm_candidates():
                    if loaded is not None and c.realpath == loaded:
                        verdict = probe_llvm(c, _llvm_variant(spectral))
                if verdict is None or not verdict["ok"]:
                    variant = _scalar_variant(spectral)
                    _warn_once(f"drjit was imported before rigsim chose a libLLVM and loaded "
                               f"{loaded or 'none'}; using {variant} (slow)")
    elif not forced:
        _warn_once(
            f"no working libLLVM for Mitsuba's llvm variants (tried: "
            f"{', '.join(c.path for c in llvm_candidates()) or 'none found'}); falling back to "
            f"{variant} -- rendering will be very slow. Install libLLVM >= 17 (e.g. libllvm19) "
            f"or set DRJIT_LIBLLVM_PATH; `rigsim doctor` shows the verdicts.")
    import mitsuba as mi

    if mi.variant() != variant:
        mi.set_variant(variant)
    with _lock:
        _state["set"] = (variant, spectral)
    return variant


def _warn_once(msg: str) -> None:
    if _state.get("warned"):
        return
    _state["warned"] = True
    log.warning("rigsim: %s", msg)


def doctor_report(test_all: bool = True) -> dict:
    """Everything `rigsim doctor` prints about the rendering backend (plain JSON-able dict).

    Keys: python, mitsuba, drjit, llvm_candidates ([{path, realpath, version, source, verdict,
    detail}]), llvm_chosen, variant, fallback_variant, notes. With ``test_all`` every candidate
    is self-tested (cached verdicts are reused); otherwise testing stops at the first working one.
    Does not import mitsuba.
    """
    variant = _llvm_variant(False)
    cands = llvm_candidates()
    rows = []
    chosen = None
    for c in cands:
        if chosen is not None and not test_all:
            rows.append({"path": c.path, "realpath": c.realpath, "version": c.version,
                         "source": c.source, "verdict": "untested", "detail": ""})
            continue
        v = probe_llvm(c, variant)
        rows.append({"path": c.path, "realpath": c.realpath, "version": c.version,
                     "source": c.source, "verdict": "ok" if v["ok"] else "bad",
                     "detail": v["detail"] + (" (cached)" if v.get("cached") else ""),
                     "seconds": v.get("seconds")})
        if v["ok"] and chosen is None:
            chosen = c
    forced = os.environ.get("RIGSIM_VARIANT")
    chosen_variant = forced or (variant if chosen is not None else SCALAR_VARIANT)
    notes = [
        f"{LLVM_VARIANT} for intensity-only rendering; {LLVM_SPECTRAL_VARIANT} on request",
        "self-tests run in a subprocess (a bad libLLVM aborts the interpreter); verdicts cached in "
        + str(cache_path()),
    ]
    if forced:
        notes.append(f"RIGSIM_VARIANT={forced} overrides the choice")
    if chosen is None:
        notes.append("no working libLLVM: scalar fallback (slow). Install libllvm19 or set "
                     "DRJIT_LIBLLVM_PATH to a libLLVM >= 17")
    if "drjit" in sys.modules:
        notes.append(f"drjit already loaded in this process with {loaded_libllvm()}")
    return {
        "python": f"{platform.python_version()} ({sys.executable})",
        "mitsuba": _pkg_version("mitsuba"),
        "drjit": _pkg_version("drjit"),
        "mitsuba_variants": _mitsuba_variants(),
        "llvm_candidates": rows,
        "llvm_chosen": chosen.path if chosen is not None else None,
        "variant": chosen_variant,
        "fallback_variant": SCALAR_VARIANT,
        "notes": notes,
    }


def set_thread_count(threads: int) -> None:
    """Dr.Jit's worker threads in this process. The libLLVM is chosen first (:func:`ensure_variant`):
    importing drjit before that would load whatever library it finds."""
    ensure_variant()
    import drjit as dr

    dr.set_thread_count(int(threads))


def release_memory() -> None:
    """Give the memory of renders that are no longer referenced back to the system: Python's garbage, Dr.Jit's
    allocation cache and the C heap's free pages (a campaign holds ~200 MB of them after its last frame)."""
    import gc

    gc.collect()
    trim_memory()


def trim_memory() -> None:
    """Dr.Jit's allocation cache and the C heap's free pages back to the system, without a garbage collection
    (cheap enough to call after every frame)."""
    import ctypes

    if "drjit" in sys.modules:
        sys.modules["drjit"].flush_malloc_cache()
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):  # not glibc
        pass


MMAP_THRESHOLD_BYTES = 1 << 20


def cap_mmap_threshold(nbytes: int = MMAP_THRESHOLD_BYTES) -> bool:
    """Serve every C allocation of at least ``nbytes`` by its own memory map, in this process and in the processes
    it starts from now on (``MALLOC_MMAP_THRESHOLD_``; a value the user set is kept).

    glibc raises its threshold (128 kB) after each large block is freed, up to 32 MB, so that the
    frames' large arrays end up on the heap, where freed space is kept and fragmented; with a fixed
    threshold a freed array goes back to the system at once. Returns False where this is not glibc."""
    import ctypes

    os.environ.setdefault("MALLOC_MMAP_THRESHOLD_", str(int(nbytes)))
    try:
        libc = ctypes.CDLL("libc.so.6")
        return bool(libc.mallopt(-3, int(os.environ["MALLOC_MMAP_THRESHOLD_"])))  # M_MMAP_THRESHOLD
    except (OSError, AttributeError, ValueError):
        return False
