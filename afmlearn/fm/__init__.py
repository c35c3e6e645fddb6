"""FM-AFM frequency-shift spectroscopy Δf(z, V): forward model, joint law fit, Kelvin parabolas.

Public API
----------
`FMSpectroscopy`, `read_fm_spectroscopy`
    The measured map (from :mod:`afmlearn.io.instruments.fm_table`).
`frequency_shift`, `law_frequency_shift`
    Giessibl's finite-amplitude Δf of a force (or a :class:`~simulator.forces.law.ForceLaw`).
`FMLaw`, `FMFit`, `model_hz`
    The shared tip--sample law (vdW + DMT + electrostatic sphere) and its joint fit.
`kelvin_parabolas`
    Per-position parabola ``Δf(V)``: the model-free CPD.
`analyze_fm`
    The whole analysis of a map: report.json (scripts/analyze_fm.py).
"""

from afmlearn.fm.fit import FMFit, model_hz
from afmlearn.fm.forward import frequency_shift, law_frequency_shift
from afmlearn.fm.kelvin import kelvin_parabolas
from afmlearn.fm.model import FMLaw
from afmlearn.io.instruments.fm_table import FMSpectroscopy, read_fm_spectroscopy

__all__ = ["FMFit", "FMLaw", "FMSpectroscopy", "frequency_shift", "kelvin_parabolas",
           "law_frequency_shift", "model_hz", "read_fm_spectroscopy"]
