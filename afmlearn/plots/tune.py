"""Figures of a study: optimisation history, parameter importances, parallel coordinates.

Drawn with :mod:`optuna.visualization.matplotlib` and written atomically as PNG. Part of the
plots layer: imported by the sweeper (the top layer), never by the analyses (afmlearn.tune).
"""

from __future__ import annotations

import logging
import warnings
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import optuna  # noqa: E402
from optuna.trial import TrialState  # noqa: E402

from afmlearn.io._atomic import atomic_path  # noqa: E402

__all__ = ["write_figures"]

log = logging.getLogger(__name__)


def write_figures(study: optuna.Study, folder: str | Path) -> dict[str, Path]:
    """``history.png``, ``importances.png``, ``parallel.png`` in ``folder``.

    A figure that needs more finished trials than the study has (importances need two
    complete trials and a searched parameter) is skipped with a log message.

    Returns
    -------
    dict of str to Path
        The figures written, by name.
    """
    from optuna.visualization import matplotlib as ovm

    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    complete = study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,))
    plots = {"history": ovm.plot_optimization_history,
             "importances": ovm.plot_param_importances,
             "parallel": ovm.plot_parallel_coordinate}
    files: dict[str, Path] = {}
    for name, draw in plots.items():
        if name == "importances" and (len(complete) < 2 or not complete[0].params):
            log.info("figure %s skipped: needs two complete trials with parameters", name)
            continue
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                ax = draw(study)
        except (ValueError, RuntimeError) as err:
            log.info("figure %s skipped: %s", name, err)
            continue
        fig = ax.figure if hasattr(ax, "figure") else ax.flat[0].figure
        fig.set_size_inches(10, 5.5)
        fig.tight_layout()
        path = out / f"{name}.png"
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=110, format="png")
        plt.close(fig)
        files[name] = path
    return files
