"""Datasets at scale: generate (process pool or Dask), store (PNG/FITS + Parquet/CSV + manifest),
resume after a kill, read back, and score an external pipeline against the truth (docs/datasets.md)."""

from rigsim.dataset.reader import Dataset, open_dataset
from rigsim.errors import DatasetError

__all__ = ["Dataset", "DatasetError", "open_dataset"]
