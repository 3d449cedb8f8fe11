"""Which of figure 26's optional stages a kernel may run: bits, so a compiled kernel can leave the rest out.

A stage whose parameter is zero is the identity (:mod:`ema_sim.models.stages`), and every element of
:mod:`.figure26` still tests its own parameter. The set here only says which stages *may* be on: an
element given a set without its bit takes the path its zero parameter would take, without the test or
the arithmetic of the identity. The fixed-step kernels are compiled once per set (:mod:`.loada`), as
JSBSim skips a component whose parameter is absent; the continuous models pass :data:`ALL`, where each
stage is decided by its parameter as before. The outputs are the same bit for bit either way.
"""

from __future__ import annotations

KCP = 1
"""Stage 5, the compliance correction gain."""
THRESHOLD = 2
"""Stage 6, the dead zone on the servo error."""
INTEGRAL = 4
"""Stage 7's integral action."""
SERVO_COMPLIANCE = 8
"""Stage 8, the aiding hinge moment's droop."""
DRIVE = 16
"""Stage 9, the current-limited velocity loop."""
LVDT_COMPLIANCE = 32
"""Stage 12, the deflection the LVDT reads."""
FEEDBACK_DELAY = 64
"""Stage 14, the delay from motion to the reading."""
IN_LOOP_FILTER = 128
"""The loop closed on a filtered LVDT."""
FREE_PLAY = 256
"""Stage 15, free play (figure 29's subsystem, or the dead zone of stage 17's spring)."""
COMPLIANCE = 512
"""Stage 16's static deflection."""
COMPLIANCE_LAG = 1024
"""Stage 16's hysteretic damping (its compliance a lag)."""
LINKAGE = 2048
"""Stage 17, the linkage mode."""

ALL = 4095
"""Every optional stage may be on: each is decided by its parameter."""
REPORT = KCP | FREE_PLAY | COMPLIANCE
"""The optional stages of the report's own figure 26 (LOADA, LOADF as flown); the others are identification's."""


def kernel_set(on: int) -> int:
    """The set a batch's kernel is compiled for: :data:`REPORT` when every instance keeps to it, else :data:`ALL`.

    Two sets per method keep compilation bounded (each is compiled once and cached) while a flight
    simulation's kernel carries none of identification's stages.

    Parameters
    ----------
    on : int
        The stages any instance runs (:func:`~.figure26.stages_on_any`).

    Returns
    -------
    int
        :data:`REPORT` or :data:`ALL`.
    """
    return REPORT if on & ~REPORT == 0 else ALL
