"""Convert an instrument file to trace format v1 (thin Hydra entry point).

Examples
--------
    python scripts/convert.py input=AZ_0052.ibw output=outputs/AZ_0052.h5
    python scripts/convert.py input=run.csv output=run.h5 calibration=outputs/cal/calibration.json
    python scripts/convert.py input=JAM.h5 output=jam_trace.h5 column=s unit=nm \
        sample_rate_hz=1.15e6 spring_constant_n_per_m=3 ...

Calibration: the file's header, replaced by calibration.json (scripts/calibrate.py), replaced
by `<field>=value` overrides (trace-format names, SI units). Unknown format, missing
calibration, a truncated or corrupted file, wrong units: prints `error: ...` (one line) and
exits with status 2.
"""

from __future__ import annotations

import hydra
from _cli import bad_input_exits
from omegaconf import DictConfig, OmegaConf

from afmlearn.io.instruments import CALIBRATION_FIELDS, READ_OPTIONS, convert_recording


@hydra.main(config_path="../conf", config_name="convert", version_base="1.3")
def main(cfg: DictConfig) -> None:
    """Run :func:`afmlearn.io.instruments.convert_recording` and list the files written."""
    with bad_input_exits(ValueError, OSError):  # RecordingError, TraceFormatError: ValueErrors
        given = OmegaConf.to_container(cfg)
        overrides = {k: given[k] for k in (*CALIBRATION_FIELDS, *READ_OPTIONS)
                     if given.get(k) is not None}
        written = convert_recording(cfg.input, cfg.output, calibration=cfg.calibration,
                                    **overrides)
    for item in written:
        print(f"wrote {item['path']} ({item['kind']}, {item['n_samples']} samples)")


if __name__ == "__main__":
    main()
