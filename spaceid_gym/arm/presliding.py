"""Presliding (hysteretic) friction: the state of the Dahl model along measured joint positions.

After a reversal of the rate a joint's Coulomb friction does not switch with the sign of the rate: it builds up over
a small displacement, as the contacts deform before they slide (Dahl 1968). Per joint, with the presliding length
``delta`` (rad), the dimensionless state ``h`` in ``[-1, 1]`` obeys::

    dh/dt = (dq - |dq| h) / delta        Coulomb torque  fc h(t)

so ``h`` is a smooth sign driven by the position, not by the rate: moving in the direction ``s = sign(dq)``, it
changes by ``dh = (s - h) |dq| dt / delta`` per distance travelled ``|dq| dt`` and relaxes exponentially toward
``s`` with that distance, ``h = s + (h0 - s) exp(-|q - q0| / delta)``. At rest ``h`` holds its value; as ``delta -> 0``
it becomes ``sign(dq)`` of the last motion. For a fixed ``delta`` the torque is linear in ``fc``.

:func:`presliding_state` integrates it exactly for positions linear between samples (a constant rate over each
step): ``h[k+1] = s_k + (h[k] - s_k) exp(-|q[k+1] - q[k]| / delta)``, ``s_k = sign(q[k+1] - q[k])``. The
recurrence is sequential in time and vectorised over the joints and any number of presliding lengths at once.
"""

from __future__ import annotations

import numpy as np

from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError


def presliding_state(q_rad: FloatArray, presliding_rad: FloatArray, initial: float = 0.0) -> FloatArray:
    """The Dahl state ``h`` at every sample of the positions ``q_rad`` (module docstring).

    Args:
        q_rad: joint positions, shape (T, n), rad.
        presliding_rad: presliding lengths ``delta`` > 0, rad: shape (n,) (one per joint) or (n, G) (G per joint,
            e.g. a grid, all integrated in one pass).
        initial: ``h`` at the first sample, in [-1, 1] (default 0: no friction stored; a joint that starts by moving
            reaches its sign after a few ``delta`` of motion).

    Returns:
        ``h``, shape (T, n) or (T, n, G), in [-1, 1].
    """
    q = np.asarray(q_rad, dtype=float)
    delta = np.asarray(presliding_rad, dtype=float)
    if q.ndim != 2 or q.shape[0] < 1:
        raise SpaceIdInputError(f"presliding_state: q_rad must have shape (T, n), got {q.shape}")
    if delta.ndim not in (1, 2) or delta.shape[0] != q.shape[1]:
        raise SpaceIdInputError(
            f"presliding_state: presliding_rad must have shape (n,) or (n, G) with n = {q.shape[1]}, got {delta.shape}"
        )
    if not (np.all(np.isfinite(delta)) and np.all(delta > 0)):
        raise SpaceIdInputError(f"presliding_state: every presliding length must be finite and > 0 rad, got {delta!r}")
    if not (np.isfinite(initial) and -1.0 <= initial <= 1.0):
        raise SpaceIdInputError(f"presliding_state: initial must be in [-1, 1], got {initial!r}")
    if not np.all(np.isfinite(q)):
        raise SpaceIdInputError("presliding_state: q_rad holds a non-finite value")
    step = np.diff(q, axis=0).reshape((q.shape[0] - 1, q.shape[1]) + (1,) * (delta.ndim - 1))
    target = np.broadcast_to(np.sign(step), (q.shape[0] - 1, *delta.shape))
    decay = np.exp(-np.abs(step) / delta)
    h = np.empty((q.shape[0], *delta.shape))
    h[0] = initial
    for k in range(q.shape[0] - 1):
        h[k + 1] = target[k] + (h[k] - target[k]) * decay[k]
    return h
