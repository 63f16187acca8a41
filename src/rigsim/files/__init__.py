"""rigsim.files: the plain files every stage reads and writes — frames (PNG, TIFF, FITS), tables
(CSV, Parquet, units in the column names) and JSON results with covariances. Imports nothing of
rigsim but :mod:`rigsim.errors`; every problem with a user's file is one
:class:`~rigsim.errors.InputError` naming the file, the line/column and what was expected.
docs/formats.md lists the files."""

from .atomic import atomic_write_bytes
from .cache import cache_dir, cached_json, source_digest
from .images import FRAME_SUFFIXES, read_image, write_image
from .results import covariance_block, read_json, symmetric_covariance, write_json
from .tables import Column, read_table, write_table

__all__ = [
           "FRAME_SUFFIXES",
           "Column",
           "atomic_write_bytes",
           "cache_dir",
           "cached_json",
           "covariance_block",
           "read_image",
           "read_json",
           "read_table",
           "source_digest",
           "symmetric_covariance",
           "write_image",
           "write_json",
           "write_table",
]
