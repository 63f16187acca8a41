"""Reading a dataset: frames as numpy arrays, the truth table as a pyarrow Table / numpy columns.

    from rigsim.dataset import open_dataset
    ds = open_dataset("data/sun")
    len(ds), ds.columns                 # frames, truth columns
    img = ds.frame(0)                   # (H, W) uint16, img[v, u]
    t = ds.truth_numpy()                # {"spot_u": array, ...}
    for i, img, row in ds:              # frames with their truth row (dict)
        ...

Nothing here needs rigsim's renderers: the files are plain PNG/FITS, Parquet, CSV and JSON.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rigsim.dataset.store import decode_image, frame_files, read_json, sha256_file
from rigsim.errors import DatasetError


class Dataset:
    def __init__(self, root, *, verify: bool = False):
        self.root = Path(root)
        if not self.root.is_dir():
            raise DatasetError(f"{self.root}: no such dataset directory")
        self.manifest = read_json(self.root / "manifest.json", "the dataset's manifest; was generation finished?")
        from rigsim.dataset.runner import _manifest_shape

        bad = _manifest_shape(self.manifest)
        if bad:
            raise DatasetError(f"{self.root}/{bad[0]}")
        self.n = int(self.manifest["n_frames"])
        self.fmt = self.manifest["image_format"]
        tp = self.root / "truth.parquet"
        if not tp.exists():
            raise DatasetError(f"{tp}: missing (the truth table)")
        import pyarrow.parquet as pq

        try:
            self.truth = pq.read_table(tp)
        except Exception as e:
            raise DatasetError(f"{tp}: corrupt Parquet file ({e})") from None
        if "frame" not in self.truth.column_names:
            raise DatasetError(f"{tp}: no 'frame' column")
        fr = self.truth.column("frame").to_numpy()
        if len(np.unique(fr)) != self.n or (self.n and (fr.min() != 0 or fr.max() != self.n - 1)):
            raise DatasetError(f"{tp}: rows cover {len(np.unique(fr))} frames, manifest says {self.n}")
        if verify:
            from rigsim.dataset.runner import verify as _verify

            bad = _verify(self.root)
            if bad:
                raise DatasetError(f"{self.root}: {len(bad)} files fail the manifest check; first: {bad[0]}")

    def __len__(self) -> int:
        return self.n

    @property
    def columns(self) -> list[str]:
        return list(self.truth.column_names)

    def truth_numpy(self) -> dict[str, np.ndarray]:
        return {c: self.truth.column(c).to_numpy(zero_copy_only=False) for c in self.truth.column_names}

    @property
    def rows_per_frame(self) -> bool:
        """False when the truth has one row per frame; True for star frames (one row per star)."""
        return self.truth.num_rows != self.n

    def row(self, index: int) -> dict:
        """The truth row of frame ``index`` (for star frames: a dict of lists, one entry per star)."""
        if not self.rows_per_frame:
            return {c: self.truth.column(c)[index].as_py() for c in self.truth.column_names}
        sel = np.flatnonzero(self.truth.column("frame").to_numpy() == index)
        return {c: [self.truth.column(c)[int(i)].as_py() for i in sel] for c in self.truth.column_names}

    def frame(self, index: int, *, check: bool = True) -> np.ndarray:
        if not (0 <= index < self.n):
            raise DatasetError(f"frame index {index}: allowed range is 0 to {self.n - 1}")
        ip, _ = frame_files(self.root, index, self.fmt)
        if not ip.exists():
            raise DatasetError(f"{ip}: missing")
        if check:
            want = self.manifest["files_sha256"].get(str(ip.relative_to(self.root)))
            if want and sha256_file(ip) != want:
                raise DatasetError(f"{ip}: checksum mismatch (corrupt or modified)")
        return decode_image(ip)

    def sidecar(self, index: int) -> dict:
        _, jp = frame_files(self.root, index, self.fmt)
        return read_json(jp, f"sidecar of frame {index}")

    def __iter__(self):
        for i in range(self.n):
            yield i, self.frame(i), self.row(i)


def open_dataset(root, *, verify: bool = False) -> Dataset:
    return Dataset(root, verify=verify)
