"""Lightning data module of simulated sweep windows, and the same windows from a recorded trace.

:class:`SweepDataModule` generates (once, cached) the HDF5 dataset of
:mod:`afmlearn.qrnn.datagen` and serves it split **by cantilever**: the validation and test
cantilevers never appear in training. Batches are dicts of tensors::

    x        (B, P, 3) float32   input period: normalised deflection u, 10 (Omega - 1), s / gap
    y        (B, horizon * P)    the following ``horizon`` periods of u (float32)
    coupling (B,) float32        share of the tip motion in modes >= 2 (label)
    coupled  (B,) float32        coupling > threshold (0/1)
    sweet    (B,) float32        point inside its sweep's sweet-spot interval (0/1)
    omega    (B,) float32        f_drive / f0
    sweep_id (B,) int64          sweep direction the window comes from (dataset-wide id)
    point    (B,) int64          index of the point in its sweep (sweep order)
    steady   (B,) float32        1 for a set-point of a set-point series, 0 for a sweep point

(``P = samples_per_period``; the representation and the label definitions are documented in
:mod:`afmlearn.qrnn.datagen`.) :func:`windows_from_trace` turns a recorded trace-format-v1 file
into the same ``x`` (and the measured following periods as ``y``) without labels.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, final

import h5py
import lightning as L
import numpy as np
import torch
from numpy.typing import NDArray
from torch.utils.data import BatchSampler, DataLoader, Dataset, RandomSampler, SequentialSampler

from afmlearn.io import Trace, read_trace
from afmlearn.qrnn.datagen import (
    DIRECTIONS,
    N_FEATURES,
    DatasetSpec,
    generate_dataset,
    input_features,
    normalise_windows,
    resample_windows,
)

__all__ = ["SweepDataModule", "windows_from_trace", "MIN_SAMPLES_PER_PERIOD"]

#: fewest raw samples per drive period accepted from a recording
MIN_SAMPLES_PER_PERIOD = 20
_STAGES = ("train", "val", "test")


@final
class _Windows(Dataset):
    """In-memory windows; indexed by a list of indices it returns a whole batch (dict)."""

    def __init__(self, arrays: dict[str, torch.Tensor]) -> None:
        self.arrays = arrays

    def __len__(self) -> int:
        return int(self.arrays["x"].shape[0])

    def __getitem__(self, index: int | Sequence[int]) -> dict[str, torch.Tensor]:
        idx = torch.as_tensor(index, dtype=torch.long)
        return {k: v[idx] for k, v in self.arrays.items()}


@final
class SweepDataModule(L.LightningDataModule):
    """Windows of simulated frequency sweeps, split by cantilever.

    Parameters
    ----------
    cache_dir : str or os.PathLike
        Folder of the cached dataset files (``qrnn-<hash>.h5``); relative paths are taken from
        the current working directory.
    spec : DatasetSpec or mapping, optional
        What to simulate (default: ``DatasetSpec()``).
    modes : int or sequence of int, optional
        Use only the cantilevers with these numbers of modes (a filter on the cached dataset,
        which holds every mode count; None: all).
    horizon : int
        Periods to predict, in [1, spec.target_periods].
    batch_size : int
        Windows per batch (>= 1).
    num_workers : int
        DataLoader worker processes (>= 0).
    split : (float, float, float)
        Train / validation / test shares of the cantilevers (> 0 each, summing to 1). The split
        is stratified by family and mode count; every part gets at least one cantilever.
    seed : int
        Seed of the split and of the training shuffle.
    progress : bool
        Progress bar while generating.
    """

    def __init__(self, *, cache_dir: str | os.PathLike[str],
                 spec: DatasetSpec | Mapping[str, Any] | None = None,
                 modes: int | Sequence[int] | None = None, horizon: int = 4,
                 batch_size: int = 64, num_workers: int = 0,
                 split: Sequence[float] = (0.7, 0.15, 0.15), seed: int = 0,
                 progress: bool = True) -> None:
        super().__init__()
        if spec is None:
            spec = DatasetSpec()
        elif not isinstance(spec, DatasetSpec):
            spec = DatasetSpec.from_dict(_plain(spec))
        self.spec = spec
        self.cache_dir = Path(cache_dir)
        self.modes = None if modes is None else tuple(int(m) for m in np.atleast_1d(modes))
        if self.modes is not None and (not self.modes or any(m not in (1, 2, 3)
                                                             for m in self.modes)):
            raise ValueError(f"modes must be None or values in {{1, 2, 3}}, got {modes!r}")
        self.horizon = _count("horizon", horizon, 1)
        if self.horizon > spec.target_periods:
            raise ValueError(f"horizon must lie in [1, spec.target_periods = "
                             f"{spec.target_periods}], got {horizon!r}")
        self.batch_size = _count("batch_size", batch_size, 1)
        self.num_workers = _count("num_workers", num_workers, 0)
        sp = np.asarray(split, dtype=float).reshape(-1)
        if sp.shape != (3,) or np.any(sp <= 0) or abs(sp.sum() - 1.0) > 1e-6:
            raise ValueError(f"split must be three shares > 0 summing to 1, got {split!r}")
        self.split = tuple(float(v) for v in sp)
        self.seed = _count("seed", seed, 0)
        self.progress = bool(progress)
        self._sets: dict[str, _Windows] = {}
        self.cantilevers_: dict[str, NDArray[np.int64]] = {}
        self._sweeps: dict[str, list[dict[str, Any]]] = {}

    # ------------------------------------------------------------------ properties
    @property
    def cache_path(self) -> Path:
        """The dataset file of this spec."""
        return self.cache_dir / f"qrnn-{self.spec.hash[:16]}.h5"

    @property
    def n_features(self) -> int:
        """Input channels per time step (3)."""
        return N_FEATURES

    @property
    def samples_per_period(self) -> int:
        """``P``: samples per drive period of ``x`` and ``y``."""
        return self.spec.samples_per_period

    # ------------------------------------------------------------------ lightning hooks
    def prepare_data(self) -> None:
        """Generate the dataset unless it is cached."""
        generate_dataset(self.cache_path, spec=self.spec, progress=self.progress)

    def setup(self, stage: str | None = None) -> None:
        """Load the cache (generating it if needed) and split it by cantilever."""
        if self._sets:
            return
        if not self.cache_path.exists():
            self.prepare_data()
        p = self.spec.samples_per_period
        with h5py.File(self.cache_path, "r") as fh:
            win = {k: fh["windows"][k][()] for k in fh["windows"]}
            pts = {k: fh["points"][k][()] for k in fh["points"]}
            swp = {k: fh["sweeps"][k][()] for k in fh["sweeps"]}
            n_modes = fh["cantilevers/n_modes"][()]
            family = fh["cantilevers/family"][()]
        parts = self._split_cantilevers(n_modes, family)
        for name, ids in zip(_STAGES, parts, strict=True):
            self.cantilevers_[name] = ids
            sel = np.flatnonzero(np.isin(win["cantilever_id"], ids))
            u = win["u"][sel]
            arrays = {
                "x": input_features(u[:, :p], win["omega"][sel], win["scale"][sel]),
                "y": np.ascontiguousarray(u[:, p:p + self.horizon * p], dtype=np.float32),
                "coupling": win["coupling"][sel].astype(np.float32),
                "coupled": win["coupled"][sel].astype(np.float32),
                "sweet": win["sweet"][sel].astype(np.float32),
                "omega": win["omega"][sel].astype(np.float32),
                "sweep_id": win["sweep_id"][sel].astype(np.int64),
                "point": win["point_index"][sel].astype(np.int64),
                # 1 for a set-point of a series (a steady record), 0 for a sweep point
                "steady": (swp["direction"][win["sweep_id"][sel]]
                           == DIRECTIONS.index("series")).astype(np.float32),
            }
            self._sets[name] = _Windows({k: torch.from_numpy(np.ascontiguousarray(v))
                                         for k, v in arrays.items()})
            self._sweeps[name] = _sweep_records(pts, swp, ids)
        for a, b in ((0, 1), (0, 2), (1, 2)):
            assert not set(parts[a]) & set(parts[b]), "cantilever split must be disjoint"

    def _split_cantilevers(self, n_modes: NDArray, family: NDArray
                           ) -> tuple[NDArray[np.int64], ...]:
        ids = np.arange(n_modes.size)
        if self.modes is not None:
            ids = ids[np.isin(n_modes, self.modes)]
        if ids.size < 3:
            raise ValueError(f"modes={self.modes}: only {ids.size} cantilever(s) in the dataset, "
                             "need >= 3 for a train/val/test split")
        rng = np.random.default_rng(self.seed)
        parts: list[list[int]] = [[], [], []]
        for key in sorted(set(zip(family[ids].tolist(), n_modes[ids].tolist(), strict=True))):
            group = rng.permutation(ids[(family[ids] == key[0]) & (n_modes[ids] == key[1])])
            n_test = int(round(self.split[2] * group.size))
            n_val = int(round(self.split[1] * group.size))
            if group.size - n_test - n_val < 1:
                n_val, n_test = 0, 0
            parts[2] += group[:n_test].tolist()
            parts[1] += group[n_test:n_test + n_val].tolist()
            parts[0] += group[n_test + n_val:].tolist()
        for k in (1, 2):  # every part needs a cantilever: move one from training if empty
            if not parts[k]:
                parts[k].append(parts[0].pop(int(rng.integers(len(parts[0])))))
        return tuple(np.sort(np.asarray(p, dtype=np.int64)) for p in parts)

    def _loader(self, name: str, *, shuffle: bool) -> DataLoader:
        if not self._sets:
            self.setup()
        data = self._sets[name]
        sampler = (RandomSampler(data, generator=torch.Generator().manual_seed(self.seed))
                   if shuffle else SequentialSampler(data))
        return DataLoader(data, batch_size=None, num_workers=self.num_workers,
                          sampler=BatchSampler(sampler, self.batch_size, drop_last=False),
                          persistent_workers=self.num_workers > 0)

    def train_dataloader(self) -> DataLoader:
        return self._loader("train", shuffle=True)

    def val_dataloader(self) -> DataLoader:
        return self._loader("val", shuffle=False)

    def test_dataloader(self) -> DataLoader:
        return self._loader("test", shuffle=False)

    def dataset(self, stage: str) -> Dataset:
        """All windows of ``stage`` (``train``, ``val`` or ``test``); index with a list."""
        if stage not in _STAGES:
            raise ValueError(f"stage must be one of {_STAGES}, got {stage!r}")
        if not self._sets:
            self.setup()
        return self._sets[stage]

    def sweeps(self, stage: str) -> list[dict[str, Any]]:
        """Per-sweep labels of ``stage`` for sweet-spot evaluation (sweep directions only:
        set-point series have no frequency interval).

        Returns
        -------
        list of dict
            One per sweep direction: ``sweep_id``, ``cantilever_id``, ``n_modes``, ``family``
            (``sweet_spot`` / ``rectangular``), ``direction`` (``forward`` / ``reverse``),
            ``omega`` (n,), ``coupling`` (n,), ``coupled`` (n,) bool, ``sweet`` (n,) bool
            (points in sweep order, index = ``point``) and ``sweet_interval``
            ``(lo, hi)`` in units of ``f0`` or None.
        """
        self.dataset(stage)
        return self._sweeps[stage]


def _sweep_records(pts: dict[str, NDArray], swp: dict[str, NDArray], ids: NDArray
                   ) -> list[dict[str, Any]]:
    from afmlearn.qrnn.datagen import FAMILIES

    out = []
    for s in np.flatnonzero(np.isin(swp["cantilever_id"], ids)):
        if DIRECTIONS[int(swp["direction"][s])] == "series":   # no frequency interval
            continue
        rows = np.flatnonzero(pts["sweep_id"] == s)
        rows = rows[np.argsort(pts["point_index"][rows])]
        lo, hi = float(swp["sweet_lo"][s]), float(swp["sweet_hi"][s])
        out.append({
            "sweep_id": int(s), "cantilever_id": int(swp["cantilever_id"][s]),
            "n_modes": int(swp["n_modes"][s]), "family": FAMILIES[int(swp["family"][s])],
            "direction": DIRECTIONS[int(swp["direction"][s])],
            "omega": pts["omega"][rows].astype(float),
            "coupling": pts["coupling"][rows].astype(float),
            "coupled": pts["coupled"][rows].astype(bool),
            "sweet": pts["sweet"][rows].astype(bool),
            "sweet_interval": None if not math.isfinite(lo) else (lo, hi),
        })
    return out


def _plain(spec: Any) -> dict[str, Any]:
    try:
        from omegaconf import DictConfig, OmegaConf
    except ImportError:  # pragma: no cover - hydra is a dependency
        DictConfig = ()  # noqa: N806
    if isinstance(spec, DictConfig):
        return OmegaConf.to_container(spec, resolve=True)
    if isinstance(spec, Mapping):
        return dict(spec)
    raise ValueError(f"spec must be a DatasetSpec or a mapping, got {type(spec).__name__}")


def _count(name: str, value: Any, low: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < low:
        raise ValueError(f"{name} must be an integer >= {low}, got {value!r}")
    return int(value)


def windows_from_trace(trace: Trace | str | os.PathLike[str], *, samples_per_period: int,
                       horizon: int, stride: float = 1.0) -> dict[str, Any]:
    """The network input of a recorded trace (one trace or a sweep), without labels.

    Windows of ``1 + horizon`` drive periods start at sample 0 and every ``stride`` periods
    after it in every row, are resampled to ``samples_per_period`` samples per drive period and
    normalised by their input period exactly as the training windows
    (:mod:`afmlearn.qrnn.datagen`). Only ``deflection_m``, ``sample_rate_hz``,
    ``resonance_frequency_hz``, ``drive_frequency_hz`` and ``gap_m`` are used; ``/labels`` is
    never read.

    Parameters
    ----------
    trace : Trace or path
        A trace, or a trace-format-v1 file (read without labels).
    samples_per_period : int
        ``P`` of the model (>= 16).
    horizon : int
        Periods after the input period (>= 1).
    stride : float
        Window step in drive periods (> 0).

    Returns
    -------
    dict
        ``x`` (N, P, 3) float32 network input; ``y`` (N, horizon P) float32 the measured
        following periods in the same normalisation; ``omega`` (N,) ``f_drive / f0``; ``row``
        (N,) int64 row of the sweep (0 for a single trace); ``start_s`` (N,) window start [s];
        ``offset_m``, ``scale_m`` (N,) normalisation (``x_m = offset + scale u``) [m];
        ``omega_rows`` (n_rows,); ``is_sweep``; ``samples_per_period``; ``horizon``.

    Raises
    ------
    ValueError
        A row shorter than ``1 + horizon`` drive periods, fewer than 20 raw samples per drive
        period, NaN/inf samples (``TraceFormatError``, a ``ValueError``, for files), a
        non-positive gap, bad arguments.
    """
    if not isinstance(trace, Trace):
        trace = read_trace(trace, labels=False)
    p = _count("samples_per_period", samples_per_period, 16)
    horizon = _count("horizon", horizon, 1)
    if not (math.isfinite(stride) and stride > 0):
        raise ValueError(f"stride must be a number > 0 (drive periods), got {stride!r}")
    defl = np.atleast_2d(np.asarray(trace.deflection_m, dtype=float))
    if not np.all(np.isfinite(defl)):
        raise ValueError("deflection_m must be finite, found NaN/inf")
    n = defl.shape[1]
    f_drive = np.broadcast_to(np.atleast_1d(np.asarray(trace.drive_frequency_hz, dtype=float)),
                              (defl.shape[0],))
    omega_rows = f_drive / trace.resonance_frequency_hz
    gap = np.asarray(trace.gap_m, dtype=float)
    n_win = 1 + horizon
    out: dict[str, list] = {k: [] for k in ("x", "y", "omega", "row", "start_s", "offset_m",
                                            "scale_m")}
    for r in range(defl.shape[0]):
        period = trace.sample_rate_hz / f_drive[r]
        if period < MIN_SAMPLES_PER_PERIOD:
            raise ValueError(
                f"sample_rate_hz: {period:.1f} samples per drive period in row {r}; at least "
                f"{MIN_SAMPLES_PER_PERIOD} are needed (sample_rate_hz >= "
                f"{MIN_SAMPLES_PER_PERIOD} * drive_frequency_hz)")
        room = n - 1 - n_win * period
        if room < 0:
            raise ValueError(
                f"deflection_m: rows of {n} samples are too short; one input period plus "
                f"horizon={horizon} periods need {math.ceil(n_win * period) + 1} samples")
        starts = np.arange(0.0, room + 1e-9, stride * period)
        if gap.ndim == 0:
            g = np.full(starts.size, float(gap))
        elif trace.is_series:                    # one rest gap per set-point (row)
            g = np.full(starts.size, float(gap[r]))
        else:                                    # a ramp: the gap at the window start
            g = np.interp(starts, np.arange(n), gap)
        if np.any(g <= 0):
            raise ValueError("gap_m must be > 0 to scale the amplitude channel, got "
                             f"min {float(np.min(g))!r}")
        w = resample_windows(defl[r], period=period, starts=starts, n_periods=n_win,
                             samples_per_period=p)
        u, offset, scale = normalise_windows(w, p)
        om = np.full(starts.size, omega_rows[r])
        out["x"].append(input_features(u[:, :p], om, scale / g))
        out["y"].append(u[:, p:].astype(np.float32))
        out["omega"].append(om)
        out["row"].append(np.full(starts.size, r, dtype=np.int64))
        out["start_s"].append(starts / trace.sample_rate_hz)
        out["offset_m"].append(offset)
        out["scale_m"].append(scale)
    result: dict[str, Any] = {k: np.concatenate(v) for k, v in out.items()}
    result.update(omega_rows=omega_rows, is_sweep=trace.is_sweep, samples_per_period=p,
                  horizon=horizon)
    return result
