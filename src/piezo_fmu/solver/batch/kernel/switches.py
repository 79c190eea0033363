"""The switch rules of the model (docs/model.md section 3) for one trajectory, named as
:mod:`piezo_fmu.model.dynamics` names them and held equal to it by the tests: at a contact onset
the impact mass captures the barrier's tip mass, at a separation the tip mass rejoins the main
body, both plastically; a body at rest on a barrier presses into it as the main spring and damper
push it."""

from .registry import source


@source(inline=True)
def capture(m, M_eq, dp, dq):
    """A contact onset: the impact mass ``m`` (kg) at ``q'`` (m/s) captures the tip mass ``M_eq`` (kg),
    which moved with the main mass at ``p'``. Returns ``q'`` just after (m/s) and the energy lost (J)
    (:func:`piezo_fmu.model.dynamics.capture`)."""
    return (m * dq + M_eq * dp) / (m + M_eq), 0.5 * m * M_eq / (m + M_eq) * (dq - dp) ** 2


@source(inline=True)
def release(M, M1, M_eq, dp, dq):
    """A separation: the tip mass ``M_eq`` (kg), which moved with the impact mass at ``q'`` (m/s),
    rejoins the main body of mass ``M1 = M - M_eq`` (kg) at ``p'``. Returns ``p'`` just after (m/s) and
    the energy lost (J) (:func:`piezo_fmu.model.dynamics.release`)."""
    return (M1 * dp + M_eq * dq) / M, 0.5 * M1 * M_eq / M * (dp - dq) ** 2


@source(inline=True)
def approach_sign(K, C, u, du, side):
    """+1 when the main spring and damper alone, at ``u = p - y`` (m) and ``u' = p' - v`` (m/s), push
    the impact mass towards the barrier on ``side`` (+1 right, -1 left), -1 when away, 0 when
    neither (or NaN) (:func:`piezo_fmu.model.dynamics.approach_sign`, as a float)."""
    towards = side * (K * u + C * du)
    if towards > 0.0:
        return 1.0
    if towards < 0.0:
        return -1.0
    return 0.0
