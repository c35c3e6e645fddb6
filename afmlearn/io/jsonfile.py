"""Plain-JSON conversion and atomic JSON files (results, models, metrics)."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from afmlearn.io._atomic import atomic_path

__all__ = ["jsonable", "write_json"]


def write_json(path: str | os.PathLike[str], data: Any) -> Path:
    """Write ``data`` as indented JSON atomically (NaN/inf become null)."""
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(jsonable(data), indent=2, allow_nan=False) + "\n")
    return path


def jsonable(tree: Any) -> Any:
    """Convert NumPy scalars/arrays and tuples to plain JSON types; NaN/inf -> None."""
    if isinstance(tree, dict):
        return {str(k): jsonable(v) for k, v in tree.items()}
    if isinstance(tree, list | tuple):
        return [jsonable(v) for v in tree]
    if isinstance(tree, np.ndarray):
        return jsonable(tree.tolist())
    if isinstance(tree, np.generic):
        return jsonable(tree.item())
    if isinstance(tree, float):
        return tree if math.isfinite(tree) else None
    if tree is None or isinstance(tree, bool | int | str):
        return tree
    return repr(tree)
