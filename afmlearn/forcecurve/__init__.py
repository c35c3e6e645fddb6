"""Static force curves: contact laws (DMT sphere, free exponent), adhesion hysteresis, and
the gain of an extension measured on the retraction.

Public API: `ContactFit`, `Branch`, `branch`, `analyse_curve`.
"""

from afmlearn.forcecurve.analysis import analyse_curve
from afmlearn.forcecurve.contact import Branch, ContactFit, branch

__all__ = ["Branch", "ContactFit", "analyse_curve", "branch"]
