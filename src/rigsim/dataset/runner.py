"""``rigsim dataset generate``: plan, render in parallel (process pool or Dask), resume, finish.

Reproducibility: every frame's parameters and seed come from ``SeedSequence([seed, index])`` in
the plan, which is written to ``plan.json`` before anything is rendered. Workers, their number,
their order, retries and restarts therefore cannot change a frame.

Resume: a rerun of the same command reads ``plan.json``, checks that it describes the same
dataset (rig file checksum, generator, seed, frames/sweep, options), and renders only the frames
that are not complete. A frame is complete when its sidecar is intact (its own checksum), belongs to
this frame's plan entry and holds the SHA-256 of its image (store.frame_complete); anything else is
rendered again. Both files are written atomically, image first (rigsim.files.atomic).

Ownership: a run holds the folder's lock (dataset.lock) from the plan to the manifest; a second run
on the same folder stops with one line naming the holder.

Faults: a task that raises, or a worker process that dies, is resubmitted (``retries`` times per
chunk; a broken process pool is rebuilt). A half-done chunk resumes at its first incomplete frame.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import platform
import re
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from rigsim.dataset.generators import GENERATORS, make_generator, worker_generator
from rigsim.dataset.ownership import dataset_lock, remove_stale_temporaries
from rigsim.dataset.store import (
    FORMAT,
    atomic_write_json,
    frame_complete,
    frame_files,
    read_json,
    sha256_file,
    sidecar_problem,
    write_frame_atomic,
)
from rigsim.errors import DatasetError
from rigsim.files.atomic import atomic_write_bytes
from rigsim.render.budget import check_disk, cpu_count, fit_processes, process_bytes

PLAN_KEYS = ("generator", "rig_sha256", "seed", "frames", "sweep", "options")
FAIL_ENV = "RIGSIM_DATASET_INJECT_FAULT"  # tests: "crash:INDEX:MARKER_DIR" or "raise:INDEX:MARKER_DIR" (once)


def software_versions() -> dict:
    import importlib.metadata as md

    out = {"python": platform.python_version(), "platform": platform.platform()}
    for p in ("rigsim", "mitsuba", "drjit", "numpy", "scipy", "opencv-python-headless", "pyarrow", "dask",
              "distributed", "astropy"):
        try:
            out[p] = md.version(p)
        except md.PackageNotFoundError:
            pass
    return out


def _maybe_inject_fault(root: Path, index: int) -> None:
    spec = os.environ.get(FAIL_ENV)
    if not spec:
        return
    mode, idx, marker_dir = spec.split(":", 2)
    if int(idx) != index:
        return
    import hashlib

    tag = hashlib.sha256(str(root.resolve()).encode()).hexdigest()[:16]
    marker = Path(marker_dir) / f"rigsim-fault-injected-{tag}-{index}"  # the test's folder, outside the dataset
    if marker.exists():
        return
    marker.write_text(mode)
    if mode == "crash":
        os._exit(3)  # the worker process dies mid-task, before writing the frame
    raise RuntimeError(f"injected fault at frame {index}")


def render_chunk(kind: str, rig_text: str, rig_source: str, opts: dict, root: str, fmt: str,
                 items: list[tuple[int, dict]]) -> list[tuple[int, str]]:
    """Worker task: render and write every frame of ``items`` that is not complete yet.

    A frame is encoded and written (fsync included) on one I/O thread while the next one renders; at
    most one write is in flight, and the task returns once every write has finished."""
    from concurrent.futures import ThreadPoolExecutor

    root_p = Path(root)
    gen = worker_generator(kind, rig_text, rig_source, opts)
    done: list = []
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="rigsim-write") as io:
        pending = None
        for index, params in items:
            if frame_complete(root_p, index, fmt, params=params):
                ip, _ = frame_files(root_p, index, fmt)
                done.append((index, sha256_file(ip)))
                continue
            _maybe_inject_fault(root_p, index)
            img, sidecar, row = gen.render(index, params)
            sidecar = dict(sidecar)
            sidecar.setdefault("dataset", {})["truth_row"] = row
            if pending is not None:
                done.append(pending.result())
            pending = io.submit(_write_frame, root_p, index, img, sidecar, fmt, params)
        if pending is not None:
            done.append(pending.result())
    return sorted(done)


def _write_frame(root: Path, index: int, img, sidecar: dict, fmt: str, params: dict) -> tuple[int, str]:
    return index, write_frame_atomic(root, index, img, sidecar, fmt, params=params)


@dataclass
class GenerateResult:
    root: Path
    n_frames: int
    n_rendered: int
    n_resumed: int
    seconds: float
    frames_per_second: float
    retries: int
    manifest: dict


def _plan_record(kind, rig_path, rig_text, seed, frames, sweep, opts, params) -> dict:
    from rigsim.dataset.store import sha256_bytes

    return {"format": FORMAT, "generator": kind, "rig_file": str(rig_path), "rig_sha256": sha256_bytes(rig_text.encode()),
            "rig_toml": rig_text, "seed": int(seed), "frames": frames, "sweep": sweep, "options": opts,
            "image_format": GENERATORS[kind].image_format, "n_frames": len(params), "frame_params": params,
            "created_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            "software": software_versions()}


def generate(rig: str, out, *, frames: int | None = None, sweep: str | None = None, seed: int = 0,
             generator: str | None = None, workers: int | None = None, scheduler: str | None = None,
             spp: int | None = None, retries: int = 2, chunk: int = 4, progress: bool = True,
             renderer: str | None = None) -> GenerateResult:
    from rigsim.rig.load import parse_rig_text, read_rig_text, resolve_rig_path

    from rigsim.render.workers import pool_context

    t0 = time.perf_counter()
    if scheduler is None:
        pool_context()  # a bad RIGSIM_START_METHOD is named before anything is written
    rig_path = resolve_rig_path(rig)
    rig_text = read_rig_text(rig_path)
    rig_table = parse_rig_text(rig_text, rig_path)
    from rigsim.dataset.generators import generator_for_rig

    kind = generator or generator_for_rig(rig_text)
    if kind not in GENERATORS:
        raise DatasetError(f"--generator {kind!r}: allowed {', '.join(sorted(GENERATORS))}")
    if (frames is None) == (sweep is None):
        raise DatasetError("give exactly one of --frames N or --sweep SPEC")
    if frames is not None and not (1 <= frames <= 10_000_000):
        raise DatasetError(f"--frames = {frames}: allowed range is 1 to 10000000")
    sd = str(rig_table.get("seed_document", "000"))
    if sd not in GENERATORS[kind].seeds:
        fits = [k for k, c in GENERATORS.items() if sd in c.seeds]
        raise DatasetError(f"--generator {kind}: renders seed-{'/'.join(GENERATORS[kind].seeds)} rigs; {rig_path} is a "
                           f"seed-{sd} rig (its generators: {', '.join(fits) or 'none'})")
    spp = GENERATORS[kind].default_spp if spp is None else spp
    if not (1 <= spp <= 65536):
        raise DatasetError(f"--spp = {spp}: allowed range is 1 to 65536")
    if renderer is not None and renderer not in getattr(GENERATORS[kind], "renderers", ()):
        allowed = getattr(GENERATORS[kind], "renderers", ())
        raise DatasetError(f"--renderer = {renderer!r}: generator {kind} " + (f"allows {', '.join(allowed)}" if allowed
                                                                             else "has one renderer (no --renderer)"))
    if workers is not None and not (1 <= workers <= 512):
        raise DatasetError(f"--workers = {workers}: allowed range is 1 to 512")
    if isinstance(scheduler, str) and not re.fullmatch(r"((tcp|tls|ucx)://)?[A-Za-z0-9_.\-\[\]:]+:[0-9]{1,5}", scheduler):
        raise DatasetError(f"--scheduler {scheduler!r}: expected a Dask scheduler address HOST:PORT or tcp://HOST:PORT")
    if not (0 <= retries <= 20):
        raise DatasetError(f"--retries = {retries}: allowed range is 0 to 20")
    opts = {"spp": int(spp)}
    if renderer is not None:
        opts["renderer"] = renderer
    gen = make_generator(kind, rig_text, str(rig_path), **opts)  # the rig is validated before anything is written
    if sweep is not None:
        from rigsim.dataset.generators.base import parse_sweep

        parse_sweep(sweep, gen.sweepable())  # and the sweep
    if not scheduler:
        fit_processes(1, int(gen.pixels_per_frame), f"{rig_path}: {gen.detector_field}")  # before anything is written
    if frames is not None:
        check_disk(out, frames, int(gen.pixels_per_frame), f"--out {out}")  # before the plan is drawn
    root = Path(out)
    if root.exists() and not root.is_dir():
        raise DatasetError(f"--out {root}: is a file; expected a folder (new or a dataset's)")
    try:
        root.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise DatasetError(f"--out {root}: cannot create the folder ({e.strerror or e})") from None
    with dataset_lock(root, "rigsim dataset generate"):
        return _generate_locked(root, t0, gen, opts, kind, rig_path, rig_text, frames, sweep, seed, workers, scheduler,
                                retries, chunk, progress)


def _generate_locked(root, t0, gen, opts, kind, rig_path, rig_text, frames, sweep, seed, workers, scheduler, retries,
                     chunk, progress) -> GenerateResult:
    for sub in ("frames", "plan.json", "manifest.json", "truth.csv", "truth.parquet"):
        if (root / sub).is_symlink():
            raise DatasetError(f"{root / sub}: is a symbolic link; rigsim writes only inside --out (remove the link)")
    fmt = gen.image_format
    plan_path = root / "plan.json"
    if plan_path.exists():
        plan = read_json(plan_path, "the dataset's plan")
        if not isinstance(plan, dict) or not isinstance(plan.get("frame_params"), list):
            raise DatasetError(f"{plan_path}: not a rigsim dataset plan; choose another --out")
        new = {"generator": kind, "rig_sha256": _plan_record(kind, rig_path, rig_text, seed, frames, sweep, opts, [])["rig_sha256"],
               "seed": int(seed), "frames": frames, "sweep": sweep, "options": opts}
        diff = [k for k in PLAN_KEYS if plan.get(k) != new[k]]
        if diff:
            k = diff[0]
            raise DatasetError(f"{root} already holds a different dataset ({k}: existing {plan.get(k)!r}, requested "
                               f"{new[k]!r}); rerun the original command to resume, or choose another --out")
        params = plan["frame_params"]
    else:
        params = gen.plan(frames, sweep, seed)
        if not params:
            raise DatasetError("the plan has no frame whose spot lands on the detector (check --sweep)")
        check_disk(root, len(params), int(gen.pixels_per_frame), f"--out {root}")  # before the plan is written
        atomic_write_json(plan_path, _plan_record(kind, rig_path, rig_text, seed, frames, sweep, opts, params))
        params = read_json(plan_path, "the dataset's plan")["frame_params"]  # as the workers and resumes see it
    if not isinstance(params, list) or not all(isinstance(p, dict) for p in params):
        raise DatasetError(f"{plan_path}: frame_params is not a list of frames; choose another --out")
    n = len(params)
    remove_stale_temporaries(root)
    todo = [i for i in range(n) if not frame_complete(root, i, fmt, params=params[i])]
    n_resumed = n - len(todo)
    chunks = [[(i, params[i]) for i in todo[k:k + chunk]] for k in range(0, len(todo), chunk)]
    w = workers or min(cpu_count(), 8)
    if todo:  # bounded up front: the memory holds the workers (fewer workers if need be), the disk the frames
        pixels = int(gen.pixels_per_frame)
        check_disk(root, len(todo), pixels, f"--out {root}")
        if not scheduler:
            fit = fit_processes(w, pixels, f"{rig_path}: {gen.detector_field}")
            if fit < w:
                print(f"rigsim: note: {w} workers of {process_bytes(pixels) / 1e9:.1f} GB each do not fit in the "
                      f"available memory; rendering with {fit}", file=sys.stderr)
                w = fit
    from tqdm import tqdm

    bar = tqdm(total=n, initial=n_resumed, desc=f"dataset {kind}", unit="frame", disable=None if progress else True)
    n_retries = 0
    t_render = time.perf_counter()
    try:
        if chunks:
            if scheduler:
                n_retries = _run_dask(scheduler, kind, rig_text, str(rig_path), opts, root, fmt, chunks, retries, bar)
            else:
                n_retries = _run_pool(w, kind, rig_text, str(rig_path), opts, root, fmt, chunks, retries, bar)
    finally:
        bar.close()
    dt_render = time.perf_counter() - t_render
    remove_stale_temporaries(root)  # of workers killed in this run (every worker has stopped)
    missing = [i for i in range(n) if not frame_complete(root, i, fmt, params=params[i])]
    if missing:
        raise DatasetError(f"{len(missing)} frames could not be generated after {retries} retries "
                           f"(first: {missing[:5]}); rerun the same command to resume")
    manifest = finish(root)
    dt = time.perf_counter() - t0
    return GenerateResult(root, n, len(todo), n_resumed, dt, len(todo) / dt_render if todo else 0.0, n_retries, manifest)


def _die_with_parent(parent: int | None = None) -> None:
    """A worker must not outlive the run that started it (a killed main process would otherwise leave
    workers rendering and writing, holding the caller's pipe): Linux's parent-death signal, and a
    watchdog thread where that is not available."""
    import signal
    import threading

    # the parent's pid comes from the parent: a worker that starts after its parent died (a slow
    # start on a busy machine) would otherwise take init's pid for its parent's and live on
    # A forkserver's child (rigsim.render.workers) has the server for its parent: the server exits when the run
    # that started it dies, and the parent-death signal follows; the watchdog watches the run itself as well.
    parent = os.getppid() if parent is None else int(parent)
    server = os.getppid()
    try:
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL), 0, 0, 0)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass

    def orphaned() -> bool:
        return os.getppid() != server or (server != parent and not _alive(parent))

    def watch():
        while True:
            if orphaned():
                os._exit(1)
            time.sleep(0.5)

    if orphaned():
        os._exit(1)
    threading.Thread(target=watch, name="rigsim-parent-watch", daemon=True).start()


def _alive(pid: int) -> bool:
    """Whether process ``pid`` runs (a zombie, killed but not yet reaped, does not)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return True
    return stat.rpartition(")")[2].split()[0] != "Z"


def _init_worker(threads: int | None, parent: int | None = None) -> None:
    """Die with the parent; one thread per worker process when several share the machine (no oversubscription)."""
    _die_with_parent(parent)
    _set_threads(threads)


def _set_threads(threads: int | None) -> None:
    """The thread policy (:mod:`rigsim.render.threads`): ``"worker"`` (every pool one thread) for one of
    several workers, else ``"render"`` with ``threads`` Dr.Jit/OpenCV threads and one BLAS thread."""
    if threads:
        from rigsim.render.threads import apply_thread_policy

        apply_thread_policy("worker" if int(threads) == 1 else "render", int(threads))


def _run_pool(workers, kind, rig_text, rig_source, opts, root, fmt, chunks, retries, bar) -> int:
    from concurrent.futures import FIRST_COMPLETED, wait
    from concurrent.futures.process import BrokenProcessPool

    from rigsim.render.workers import process_pool

    threads = 1 if workers > 1 else None
    attempts = {k: 0 for k in range(len(chunks))}
    pending = set(range(len(chunks)))
    n_retries = 0
    while pending:
        # Mitsuba/Dr.Jit state must not be forked: the workers start from a forkserver that never loads them
        with process_pool(min(workers, len(pending)), "rigsim.dataset.runner:_init_worker",
                          (threads, os.getpid())) as ex:
            futs = {ex.submit(render_chunk, kind, rig_text, rig_source, opts, str(root), fmt, chunks[k]): k
                    for k in sorted(pending)}
            broken = False
            while futs:
                done, _ = wait(futs, return_when=FIRST_COMPLETED)
                for f in done:
                    k = futs.pop(f)
                    try:
                        res = f.result()
                        pending.discard(k)
                        bar.update(sum(1 for _ in res))
                    except BrokenProcessPool:
                        broken = True
                    except Exception as e:  # the task raised: retry it
                        attempts[k] += 1
                        n_retries += 1
                        if attempts[k] > retries:
                            raise DatasetError(f"frames {[i for i, _ in chunks[k]]}: failed {attempts[k]} times: {e}") from e
                        futs[ex.submit(render_chunk, kind, rig_text, rig_source, opts, str(root), fmt, chunks[k])] = k
                if broken:
                    break
        if broken:  # a worker died: every unfinished chunk is retried in a fresh pool
            n_retries += 1
            for k in pending:
                attempts[k] += 1
                if attempts[k] > retries + 1:
                    raise DatasetError(f"worker processes keep dying (frames {[i for i, _ in chunks[k]]})")
            chunks = [[(i, p) for i, p in c if not frame_complete(root, i, fmt, params=p)] for c in chunks]
            pending = {k for k in pending if chunks[k]}
            bar.n = bar.total - sum(len(chunks[k]) for k in pending)
            bar.refresh()
    return n_retries


def _dask_task(kind, rig_text, rig_source, opts, root, fmt, items):
    _set_threads(1)
    return render_chunk(kind, rig_text, rig_source, opts, root, fmt, items)


PROBE_PREFIX = ".rigsim-worker-probe."
WORKER_WAIT_S = 30.0  # how long the client waits for a first worker to join the scheduler


def probe_folder(root: str, token: str) -> str | None:
    """Run on a Dask worker: None when ``root`` is the client's dataset folder (the token file the client wrote
    there is visible, with the client's token) and the worker can create files in its ``frames`` folder; else why
    not, in a few words."""
    import tempfile

    p = Path(root)
    if not p.is_absolute():
        return f"{root} is not an absolute path"
    if not p.is_dir():
        return f"no folder {root} on this worker"
    try:
        if (p / f"{PROBE_PREFIX}{token}.tmp").read_text() != token:
            raise OSError
    except OSError:
        return f"{root} on this worker is not the client's folder (another file system: the folder is not shared)"
    try:
        (p / "frames").mkdir(exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=p / "frames", prefix=PROBE_PREFIX, suffix=".tmp")
        os.close(fd)
        os.unlink(tmp)
    except OSError as e:
        return f"cannot write in {p / 'frames'} ({e.strerror or e})"
    return None


def check_workers(client, root: Path, scheduler) -> int:
    """Before any task is sent: every worker of the cluster sees the dataset folder at the client's absolute path
    and can write in it (:func:`probe_folder`); one line naming the first that cannot. Returns the worker count."""
    import secrets

    try:
        client.wait_for_workers(1, timeout=WORKER_WAIT_S)
    except (TimeoutError, OSError) as e:
        raise DatasetError(f"--scheduler {scheduler!r}: no worker joined the scheduler within {WORKER_WAIT_S:g} s "
                           f"({type(e).__name__}); start workers (dask worker {scheduler})") from None
    token = secrets.token_hex(16)
    marker = Path(root) / f"{PROBE_PREFIX}{token}.tmp"
    atomic_write_bytes(marker, token.encode())
    try:
        answers = client.run(probe_folder, str(root), token)
    finally:
        marker.unlink(missing_ok=True)
    bad = {w: why for w, why in sorted(answers.items()) if why}
    if bad:
        w, why = next(iter(bad.items()))
        more = f" (and {len(bad) - 1} other worker(s))" if len(bad) > 1 else ""
        raise DatasetError(f"--scheduler {scheduler!r}: worker {w} cannot reach --out: {why}{more}; put --out on a "
                           "file system every worker mounts at the same path")
    return len(answers)


def _run_dask(scheduler, kind, rig_text, rig_source, opts, root, fmt, chunks, retries, bar) -> int:
    try:
        from distributed import Client, as_completed
    except ImportError:  # pragma: no cover
        raise DatasetError("--scheduler needs dask.distributed (pip install 'dask[distributed]')") from None
    client = scheduler if not isinstance(scheduler, str) else None  # a Client object is used as is
    own = False
    root = Path(os.path.abspath(root))  # the workers run in other folders (and on other hosts): never a relative path
    if client is None:
        try:
            client = Client(scheduler, timeout="10s")
            own = True
        except (OSError, ValueError, TypeError) as e:
            raise DatasetError(f"--scheduler {scheduler!r}: cannot connect ({e})") from None
    try:
        check_workers(client, root, scheduler if isinstance(scheduler, str) else "(client)")
        futs = client.map(_dask_task, [kind] * len(chunks), [rig_text] * len(chunks), [rig_source] * len(chunks),
                          [opts] * len(chunks), [str(root)] * len(chunks), [fmt] * len(chunks), chunks,
                          retries=retries, pure=False)
        for f in as_completed(futs):
            res = f.result()
            bar.update(len(res))
    finally:
        if own:
            client.close()
    return 0


# ------------------------------------------------------------------ finish: truth table + manifest

def collect_rows(root: Path, n: int, fmt: str) -> list[dict]:
    rows = []
    for i in range(n):
        _, jp = frame_files(root, i, fmt)
        sc = read_json(jp, f"sidecar of frame {i}")
        try:
            r = sc["dataset"]["truth_row"]
            rows.extend(r if isinstance(r, list) else [r])
        except KeyError:
            raise DatasetError(f"{jp}: no dataset.truth_row (not written by rigsim dataset generate)") from None
    return rows


def write_truth_table(root: Path, rows: list[dict]) -> tuple[Path, Path]:
    import pyarrow as pa
    import pyarrow.csv as pcsv
    import pyarrow.parquet as pq

    cols = list(rows[0].keys())
    for r in rows[1:]:
        for k in r:
            if k not in cols:
                cols.append(k)
    table = pa.table({c: [r.get(c) for r in rows] for c in cols})
    pq_path, csv_path = root / "truth.parquet", root / "truth.csv"
    buf = pa.BufferOutputStream()
    pq.write_table(table, buf)
    atomic_write_bytes(pq_path, buf.getvalue().to_pybytes())
    buf = pa.BufferOutputStream()
    pcsv.write_csv(table, buf)
    atomic_write_bytes(csv_path, buf.getvalue().to_pybytes())
    return pq_path, csv_path


def finish(root) -> dict:
    """Write truth.parquet, truth.csv and manifest.json from the complete frames."""
    root = Path(root)
    plan = read_json(root / "plan.json", "the dataset's plan")
    n, fmt = int(plan["n_frames"]), plan["image_format"]
    rows = collect_rows(root, n, fmt)  # one row per frame, or per star for star frames
    write_truth_table(root, rows)
    files = {}
    for p in sorted([root / "plan.json", root / "truth.parquet", root / "truth.csv"]
                    + [q for i in range(n) for q in frame_files(root, i, fmt)]):
        files[str(p.relative_to(root))] = sha256_file(p)
    man = {"format": FORMAT, "generator": plan["generator"], "rig_file": plan["rig_file"], "rig_sha256": plan["rig_sha256"],
           "seed": plan["seed"], "frames": plan["frames"], "sweep": plan["sweep"], "options": plan["options"],
           "n_frames": n, "image_format": fmt, "software": software_versions(),
           "frame_seeds": [p["seed"] for p in plan["frame_params"]],
           "truth_columns": list(rows[0].keys()), "files_sha256": files,
           "finished_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")}
    atomic_write_json(root / "manifest.json", man)
    return man


def verify(root, progress: bool = False) -> list[str]:
    """Problems found (empty: the dataset is whole); ``progress``: a bar over the files on a terminal. The manifest's shape is checked; every planned frame,
    sidecar and table must be listed and match its checksum; every sidecar must be intact and belong to its
    plan entry; a listed path that leaves the folder is refused (never read); files the manifest does not
    list are reported as extra."""
    root = Path(root)
    man = read_json(root / "manifest.json", "the dataset's manifest")
    plan = read_json(root / "plan.json", "the dataset's plan")
    bad = _manifest_shape(man)
    if bad:
        return bad
    if not isinstance(plan, dict) or not isinstance(plan.get("frame_params"), list) or plan.get("n_frames") != man["n_frames"]:
        return [f"plan.json: does not describe the manifest's {man['n_frames']} frames"]
    n, fmt, files = man["n_frames"], man["image_format"], man["files_sha256"]
    resolved_root = root.resolve()
    listed = set()
    from tqdm import tqdm

    for rel, want in tqdm(files.items(), total=len(files), desc="verify", unit="file", leave=False,
                          disable=None if progress else True):
        p = root / rel
        if Path(rel).is_absolute() or ".." in Path(rel).parts or not p.resolve().is_relative_to(resolved_root):
            bad.append(f"{rel}: path leaves the dataset folder (not read)")
            continue
        listed.add(Path(rel).as_posix())
        if p.is_symlink():
            bad.append(f"{rel}: is a symbolic link (not read)")
        elif not p.is_file():
            bad.append(f"{rel}: missing")
        elif sha256_file(p) != want:
            bad.append(f"{rel}: checksum mismatch (corrupt or modified)")
    planned = ["plan.json", "truth.parquet", "truth.csv"] + [q.relative_to(root).as_posix() for i in range(n)
                                                             for q in frame_files(root, i, fmt)]
    bad += [f"{rel}: planned but not in the manifest" for rel in planned if rel not in listed]
    for i in range(n):
        _, jp = frame_files(root, i, fmt)
        if jp.is_file() and not jp.is_symlink():
            why = sidecar_problem(jp, i, plan["frame_params"][i])
            if why:
                bad.append(f"{jp.relative_to(root).as_posix()}: {why}")
    from rigsim.dataset.ownership import BOOKKEEPING

    for dirpath, dirnames, filenames in os.walk(root):  # symlinked folders are not followed
        for f in filenames:
            rel = (Path(dirpath) / f).relative_to(root).as_posix()
            if rel not in listed and rel != "manifest.json" and rel not in BOOKKEEPING:
                bad.append(f"{rel}: extra file (not in the manifest)")
    return bad


def _manifest_shape(man) -> list[str]:
    """The manifest's schema, one line per violation."""
    if not isinstance(man, dict):
        return [f"manifest.json: a JSON object expected, found {type(man).__name__}"]
    bad = []
    if man.get("format") != FORMAT:
        bad.append(f"manifest.json: format = {man.get('format')!r}, expected {FORMAT!r}")
    n = man.get("n_frames")
    if not isinstance(n, int) or isinstance(n, bool) or n < 1:
        bad.append(f"manifest.json: n_frames = {n!r}, expected an integer >= 1")
    if man.get("image_format") not in ("png", "fits"):
        bad.append(f"manifest.json: image_format = {man.get('image_format')!r}, expected 'png' or 'fits'")
    files = man.get("files_sha256")
    if not isinstance(files, dict) or not files:
        bad.append("manifest.json: files_sha256 must be an object of path: SHA-256, found "
                   + (type(files).__name__ if not isinstance(files, dict) else "an empty one"))
    else:
        for rel, h in files.items():
            if not (isinstance(h, str) and len(h) == 64 and all(c in "0123456789abcdef" for c in h)):
                bad.append(f"manifest.json: files_sha256[{rel!r}] = {h!r} is not a SHA-256")
    return bad


def describe(root) -> str:
    man = read_json(Path(root) / "manifest.json", "the dataset's manifest")
    return json.dumps({k: man[k] for k in ("generator", "rig_file", "seed", "frames", "sweep", "n_frames", "image_format")})
