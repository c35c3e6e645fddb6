"""Reading and writing traces: the trace file format (design.md section 2) and datasets.

Public API
----------
`Trace`, `Labels`
    One recording in SI units (single record, ramp, sweep, set-point series, lock-in
    curves), and the truth behind a simulated one.
`Experiment`
    The observations of one file that share the cantilever and the tip-sample law (what
    identification and diagnosis fit); `Experiment.read`, `Experiment.from_trace`.
`read_trace`, `TraceReader`, `read_rows`
    Load a file whole, or a sweep row by row; labels only when asked for.
`write_trace`, `TraceWriter`
    Write a `Trace` atomically, or stream rows / blocks straight to disk.
`write_manifest`, `iter_traces`, `shard_path`
    Folders of shard files with a ``manifest.json``.
`TraceFormatError`
    Raised for files that break the format.
`jsonable`, `write_json`
    Plain-JSON conversion (NaN/inf -> null) and atomic JSON files.
"""

from afmlearn.io._format import FORMAT, FORMAT_VERSION
from afmlearn.io.dataset import MANIFEST, iter_traces, shard_path, write_manifest
from afmlearn.io.errors import TraceFormatError
from afmlearn.io.experiment import EXPERIMENT_KINDS, Experiment
from afmlearn.io.jsonfile import jsonable, write_json
from afmlearn.io.labels import Labels
from afmlearn.io.reader import TraceReader, read_rows, read_trace
from afmlearn.io.trace import SEGMENT_APPROACH, SEGMENT_RETRACT, Trace
from afmlearn.io.writer import TraceWriter, write_trace

__all__ = [
    "EXPERIMENT_KINDS",
    "Experiment",
    "FORMAT",
    "FORMAT_VERSION",
    "MANIFEST",
    "SEGMENT_APPROACH",
    "SEGMENT_RETRACT",
    "Labels",
    "Trace",
    "TraceFormatError",
    "TraceReader",
    "TraceWriter",
    "iter_traces",
    "jsonable",
    "read_rows",
    "read_trace",
    "shard_path",
    "write_json",
    "write_manifest",
    "write_trace",
]
