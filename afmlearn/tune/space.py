"""Search space of a study, written in Hydra's sweep syntax.

``hydra.sweeper.params`` (and sweep overrides on the command line) map a config path to one of

- ``interval(a, b)`` -- a float drawn in ``[a, b]`` (``int(interval(a, b))``: an integer);
  ``tag(log, interval(a, b))`` draws it on a log scale,
- ``range(start, stop[, step])`` -- integers (or floats) ``start, start + step, ... < stop``, as
  Python's ``range`` (``stop`` excluded); ``shuffle(range(...))`` makes them categorical,
- ``choice(a, b, ...)`` -- categorical (str, int, float, bool or null),
- a plain value -- fixed for every trial (passed through as an override, not searched).

Everything else (``glob(...)``, other tags, ``tag(log, choice(...))``, a log range) is rejected
with a :class:`ValueError` naming the parameter, before any trial runs.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, final

from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.core.override_parser.types import (
    ChoiceSweep,
    IntervalSweep,
    Override,
    RangeSweep,
    Transformer,
)
from optuna.distributions import (
    BaseDistribution,
    CategoricalDistribution,
    FloatDistribution,
    IntDistribution,
)

__all__ = ["SearchSpace", "format_value"]

_SCALAR = (str, int, float, bool, type(None))


def format_value(value: Any) -> str:
    """``value`` in Hydra's override syntax (``null``, ``true``, floats with full precision)."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else str(value)
    if isinstance(value, int):
        return str(value)
    text = str(value)
    if text and all(c.isalnum() or c in "_-./:+" for c in text):
        return text
    return "'" + text.replace("\\", "\\\\").replace("'", "\\'") + "'"


def _distribution(override: Override) -> BaseDistribution:
    """The Optuna distribution of one sweep override; ValueError for unsupported sweeps."""
    name = override.get_key_element()
    value = override.value()
    tags = set(getattr(value, "tags", set()) or set())
    if isinstance(value, ChoiceSweep):
        if tags:
            raise ValueError(f"hydra.sweeper.params.{name}: tags {sorted(tags)} are not supported "
                             "on choice(...) (supported: tag(log, interval(a, b)))")
        choices = list(override.sweep_iterator(transformer=Transformer.encode))
        bad = [c for c in choices if not isinstance(c, _SCALAR)]
        if bad:
            raise ValueError(f"hydra.sweeper.params.{name}: choice(...) needs str, int, float, "
                             f"bool or null values, got {bad[0]!r}")
        return CategoricalDistribution(choices)
    if isinstance(value, RangeSweep):
        if tags:
            raise ValueError(f"hydra.sweeper.params.{name}: tags {sorted(tags)} are not supported "
                             "on range(...) (use tag(log, interval(a, b)) for a log scale)")
        values = list(override.sweep_iterator(transformer=Transformer.encode))
        if not values:
            raise ValueError(f"hydra.sweeper.params.{name}: {override.input_line} "
                             "is empty")
        if value.shuffle:
            return CategoricalDistribution(values)
        step = value.step
        if all(isinstance(v, int) for v in (value.start, value.stop, step)):
            return IntDistribution(int(values[0]), int(values[-1]), step=int(step))
        return FloatDistribution(float(values[0]), float(values[-1]), step=float(step))
    if isinstance(value, IntervalSweep):
        unknown = tags - {"log"}
        if unknown:
            raise ValueError(f"hydra.sweeper.params.{name}: unsupported tag(s) {sorted(unknown)} "
                             "(supported: log)")
        log = "log" in tags
        lo, hi = value.start, value.end
        if lo is None or hi is None or not lo < hi:
            raise ValueError(f"hydra.sweeper.params.{name}: interval needs start < end, got "
                             f"{override.input_line}")
        if log and lo <= 0:
            raise ValueError(f"hydra.sweeper.params.{name}: tag(log, interval(a, b)) needs a > 0, "
                             f"got a = {lo}")
        if isinstance(lo, int) and isinstance(hi, int):
            return IntDistribution(lo, hi, log=log)
        return FloatDistribution(float(lo), float(hi), log=log)
    raise ValueError(f"hydra.sweeper.params.{name}: unsupported distribution "
                     f"{override.input_line!r} (supported: interval(a, b), "
                     "tag(log, interval(a, b)), range(start, stop[, step]), choice(...))")


@final
@dataclass(frozen=True)
class SearchSpace:
    """The searched parameters (Optuna distributions) and the fixed overrides of a study.

    Attributes
    ----------
    distributions : dict of str to BaseDistribution
        Config path -> distribution, in the order given.
    fixed : tuple of str
        Plain overrides (``key=value``) passed unchanged to every trial's job.
    """

    distributions: dict[str, BaseDistribution] = field(default_factory=dict)
    fixed: tuple[str, ...] = ()

    @classmethod
    def parse(cls, params: Mapping[str, Any] | None, arguments: Iterable[str] = ()
              ) -> SearchSpace:
        """Parse ``hydra.sweeper.params`` and the command-line ``arguments``.

        Parameters
        ----------
        params : mapping of str to str or scalar, or None
            Config path -> sweep expression (``"interval(1e-4, 1e-2)"``) or fixed value.
        arguments : iterable of str
            Command-line overrides; sweeps among them are searched too, the rest fixed.

        Raises
        ------
        ValueError
            An override Hydra cannot parse or an unsupported distribution, naming the parameter.
        """
        texts = [f"{k}={v}" for k, v in (params or {}).items()] + list(arguments)
        try:
            parsed = OverridesParser.create().parse_overrides(texts)
        except Exception as err:  # hydra.errors.OverrideParseException and friends
            raise ValueError(f"hydra.sweeper.params: cannot parse the search space: {err}"
                             ) from None
        distributions: dict[str, BaseDistribution] = {}
        fixed: dict[str, str] = {}
        for override in parsed:
            key = override.get_key_element()
            if override.is_sweep_override():
                distributions[key] = _distribution(override)
                fixed.pop(key, None)
            else:
                fixed[key] = str(override.input_line)
                distributions.pop(key, None)
        return cls(distributions=distributions, fixed=tuple(fixed.values()))

    def overrides(self, params: Mapping[str, Any]) -> list[str]:
        """Hydra overrides of one trial: the fixed ones, then ``path=value`` per parameter."""
        return [*self.fixed, *(f"{k}={format_value(params[k])}" for k in self.distributions)]

    def example(self) -> dict[str, Any]:
        """One admissible value per parameter (the low end or the first choice), for checks."""
        out: dict[str, Any] = {}
        for key, dist in self.distributions.items():
            out[key] = dist.choices[0] if isinstance(dist, CategoricalDistribution) else dist.low
        return out

    def contains(self, key: str, value: Any) -> bool:
        """Whether ``value`` is a point of parameter ``key``'s distribution."""
        d = self.distributions[key]
        if isinstance(d, CategoricalDistribution):
            return any(value == c and type(value) is type(c) for c in d.choices)
        if isinstance(value, bool) or not isinstance(value, int | float):
            return False
        if isinstance(d, IntDistribution) and value != int(value):
            return False
        if not d.low <= value <= d.high:
            return False
        if d.step is None:
            return True
        k = (value - d.low) / d.step
        return abs(k - round(k)) < 1e-9

    def suggest(self, trial: Any) -> dict[str, Any]:
        """Draw every parameter of ``trial`` (an :class:`optuna.Trial`) from its distribution."""
        out: dict[str, Any] = {}
        for key, d in self.distributions.items():
            if isinstance(d, CategoricalDistribution):
                out[key] = trial.suggest_categorical(key, d.choices)
            elif isinstance(d, IntDistribution):
                out[key] = trial.suggest_int(key, d.low, d.high, step=d.step, log=d.log)
            else:
                assert isinstance(d, FloatDistribution)
                out[key] = trial.suggest_float(key, d.low, d.high, step=d.step, log=d.log)
        return out
