"""Layout of the canonical dimensionless coefficient vector read by the numba force kernel.

Every force model maps its parameters onto this vector (``AbstractForceModel.coefficients``).
The kernel (``forces/_kernel.py``) evaluates the superposition of all terms; a coefficient of
zero switches its term off. All quantities are dimensionless (lengths / ``L_ref``, forces /
``k L_ref``, time * ``omega0``). ``delta = a0 - z`` is the indentation.

=========  =====================================================================================
index      term (positive = repulsive)
=========  =====================================================================================
A0         contact onset ``a0``
CONTACT    1 if the model has a contact branch (a regime state switched by located events)
VDW        ``c``: ``-c / z**2`` out of contact, ``-c / a0**2`` in contact (DMT continuity)
LJ_REP     ``+c / z**8`` at all gaps (Lennard-Jones repulsion)
E_CONT     ``E``: ``+E * delta**p`` in contact
P_CONT     contact exponent ``p``
VISCO      ``c_v``: ``+c_v * delta**q * delta_dot`` in contact (``delta_dot = -z_dot``)
Q_VISCO    exponent ``q`` of the viscoelastic term
EXPD       ``c_e``: ``-c_e * exp(-z / z_b) * z_dot`` at all gaps
ZB         decay length ``z_b``
ES         ``c_es``: ``-c_es / (z (z + R_es))`` at all gaps (electrostatic sphere)
R_ES       ``R_es``
SPH        ``s``: ``-s / (z**2 (z + 2 R_s)**2)`` at all gaps (exact sphere--plane van der Waals)
R_SPH      ``R_s``
JKR        1 for the hysteretic JKR contact (replaces the ``E delta**p - c/a0**2`` branch)
JKR_ALPHA  ``alpha`` in ``F = alpha a**3 - beta a**1.5``
JKR_BETA   ``beta``
JKR_R      ``R_j`` in ``delta = a**2 / R_j - c_j sqrt(a)``
JKR_C      ``c_j``
BREAK      indentation (<= 0) at which contact breaks on retraction; 0 = where it formed
=========  =====================================================================================
"""

A0 = 0
CONTACT = 1
VDW = 2
LJ_REP = 3
E_CONT = 4
P_CONT = 5
VISCO = 6
Q_VISCO = 7
EXPD = 8
ZB = 9
ES = 10
R_ES = 11
SPH = 12
R_SPH = 13
JKR = 14
JKR_ALPHA = 15
JKR_BETA = 16
JKR_R = 17
JKR_C = 18
BREAK = 19
N_COEFFICIENTS = 20
