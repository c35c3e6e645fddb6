"""Quasi-recurrent networks for AFM: orbit prediction from one period and a mode-coupling flag.

Layer and networks (plain PyTorch)
    `QRNNLayer`, `QRNN` with pooling strategies `FPooling`, `FOPooling`, `IFOPooling`; scans
    `fo_pool` (chunked, numerically safe) and `fo_pool_reference` (loop); sequence networks
    `QRNNNet`, `LSTMNet`, `GRUNet` (`AbstractSequenceNet.encode`).
Data
    `DatasetSpec`, `generate_dataset` (simulated sweeps cached in HDF5), `SweepDataModule`
    (split by cantilever), `windows_from_trace` (recorded traces, no labels).
Model, training, evaluation
    `OrbitModule` with forecast strategies `DirectForecast`, `AutoregressiveForecast` and
    orbit losses `PeriodNRMSELoss` (default), `MSEOrbitLoss`;
    `train(cfg)` (Hydra config ``conf/train_qrnn.yaml``), `export_checkpoint`, `evaluate`.
Calibration and evidence for other analyses (issue 15)
    `coupling_probability` (calibrated probability per trace / set-point, `CouplingEvidence`),
    `CouplingCalibration`, `PlattCalibrator`, `IsotonicCalibrator`, `flag_threshold`.
Coupling, inference, interpretation
    `CouplingFlag`, `trace_scores`, `sweet_spot_interval`, `interval_iou`, `roc_auc`;
    `infer(trace_path, out_dir)`, `load_module`, `coupling_summary`, `DEFAULT_CHECKPOINT`;
    `interpret_sweep`, `rank_units`, `point_activations`.

Gate convention: the paper's forget gate ``f``, ``c_t = f_t c_{t-1} + (1 - f_t) z_t`` (``f`` near
1 remembers); the old CUDA code passes ``1 - f``. See docs/qrnn.md.

Submodule and function share a name for `train`, `infer` and `evaluate`; the package attribute
is the function (``from afmlearn.qrnn.train import train`` works as well).
"""

from afmlearn.qrnn.calibration import (
    CouplingCalibration,
    IsotonicCalibrator,
    PlattCalibrator,
    flag_threshold,
)
from afmlearn.qrnn.coupling import (
    CouplingFlag,
    interval_iou,
    roc_auc,
    sweet_spot_interval,
    trace_scores,
)
from afmlearn.qrnn.data import SweepDataModule, windows_from_trace
from afmlearn.qrnn.datagen import DatasetSpec, dataset_summary, generate_dataset
from afmlearn.qrnn.evaluate import evaluate
from afmlearn.qrnn.evidence import CouplingEvidence, coupling_probability
from afmlearn.qrnn.forecast import AbstractForecast, AutoregressiveForecast, DirectForecast
from afmlearn.qrnn.infer import (
    DEFAULT_CHECKPOINT,
    coupling_summary,
    infer,
    load_module,
    predict_trace,
)
from afmlearn.qrnn.interpret import (
    SweepInterpretation,
    UnitRanking,
    interpret_sweep,
    point_activations,
    rank_units,
)
from afmlearn.qrnn.layer import (
    QRNN,
    AbstractPooling,
    FOPooling,
    FPooling,
    IFOPooling,
    QRNNCarry,
    QRNNLayer,
)
from afmlearn.qrnn.losses import AbstractOrbitLoss, MSEOrbitLoss, PeriodNRMSELoss
from afmlearn.qrnn.module import OrbitModule
from afmlearn.qrnn.networks import AbstractSequenceNet, GRUNet, LSTMNet, QRNNNet
from afmlearn.qrnn.scan import (
    AbstractScan,
    ChunkedScan,
    DoublingScan,
    ReferenceScan,
    fo_pool,
    fo_pool_reference,
    linear_scan,
    linear_scan_reference,
    prefix_scan,
)
from afmlearn.qrnn.train import export_checkpoint, train

__all__ = [
    "DEFAULT_CHECKPOINT",
    "QRNN",
    "AbstractForecast",
    "AbstractOrbitLoss",
    "AbstractPooling",
    "AbstractScan",
    "AbstractSequenceNet",
    "AutoregressiveForecast",
    "ChunkedScan",
    "CouplingCalibration",
    "CouplingEvidence",
    "CouplingFlag",
    "DatasetSpec",
    "DirectForecast",
    "DoublingScan",
    "FOPooling",
    "FPooling",
    "GRUNet",
    "IFOPooling",
    "IsotonicCalibrator",
    "LSTMNet",
    "MSEOrbitLoss",
    "OrbitModule",
    "PeriodNRMSELoss",
    "PlattCalibrator",
    "QRNNCarry",
    "QRNNLayer",
    "QRNNNet",
    "ReferenceScan",
    "SweepDataModule",
    "SweepInterpretation",
    "UnitRanking",
    "coupling_probability",
    "coupling_summary",
    "dataset_summary",
    "evaluate",
    "export_checkpoint",
    "flag_threshold",
    "fo_pool",
    "fo_pool_reference",
    "generate_dataset",
    "infer",
    "interpret_sweep",
    "interval_iou",
    "linear_scan",
    "linear_scan_reference",
    "load_module",
    "point_activations",
    "predict_trace",
    "prefix_scan",
    "rank_units",
    "roc_auc",
    "sweet_spot_interval",
    "train",
    "trace_scores",
    "windows_from_trace",
]
