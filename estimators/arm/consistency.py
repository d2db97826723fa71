"""Physical consistency of rigid-body inertial parameters, and the log-Cholesky parameterisation that enforces it.

Conventions
-----------
* ``params10`` is pinocchio's order ``[m, hx, hy, hz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]``: mass (kg), first
  moment ``h = m c`` (kg m, ``c`` the CoM in the link frame) and the rotational inertia **about the link
  frame origin** with link-frame axes (kg m^2), as :func:`pinocchio.Inertia.toDynamicParameters` gives it.
* The **pseudo-inertia** (Wensing, Kim and Slotine 2017) is the 4x4 second-moment matrix of the mass
  distribution, ``J = integral [r; 1][r; 1]^T dm = [[Sigma, h], [h^T, m]]`` with
  ``Sigma = integral r r^T dm = tr(I)/2 E - I`` (kg m^2).

Physical consistency
--------------------
A mass distribution with positive density has ``J`` positive definite, and every ``J > 0`` comes from
one (Wensing et al. 2017, "Linear matrix inequalities for physically consistent inertial parameter
identification"). ``J > 0`` implies ``m > 0``, a positive-definite inertia about the CoM and the triangle
inequalities ``I1 + I2 >= I3`` of its principal moments; it is stricter than those (it also bounds the
inertia below by the spread the CoM offset implies). :func:`is_physically_consistent` tests it.
Friction coefficients (Coulomb, viscous) are consistent when ``>= 0``.

Log-Cholesky parameterisation
-----------------------------
(Rucker and Wensing 2022, "Smooth parameterization of rigid-body inertia".) Ten unconstrained numbers
``z = [alpha, d1, d2, d3, s12, s23, s13, t1, t2, t3]`` give

``U = exp(alpha) [[exp(d1), s12, s13, t1], [0, exp(d2), s23, t2], [0, 0, exp(d3), t3], [0, 0, 0, 1]]``

and ``J = U U^T``: positive definite for every real ``z``, and every ``J > 0`` has exactly one such
factor. Read physically: ``m = exp(2 alpha)``, the CoM ``c = t`` (m), and ``A = [[e^d1, s12, s13],
[0, e^d2, s23], [0, 0, e^d3]]`` is the upper-triangular square root of the CoM second moment per unit
mass, ``Sigma_c / m = A A^T`` (m^2): ``d`` are log-lengths, ``s`` lengths. A swarm that moves ``z`` in
any box therefore only ever visits physically consistent bodies, and the box is set in physical units
(mass range, link size) by :class:`PhysicalConsistency`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.physics.inertia import inertia_matrix_from_entries

IntArray = NDArray[np.intp]

#: names of the 10 log-Cholesky coordinates of one body, in order
LOG_CHOLESKY_NAMES = ("alpha", "d1", "d2", "d3", "s12", "s23", "s13", "t1_m", "t2_m", "t3_m")

#: (row, column) of the 6 inertia entries of params10 (pinocchio order Ixx, Ixy, Iyy, Ixz, Iyz, Izz)
_ENTRIES = ((0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2))

#: reverses the order of 3 axes: turns the lower Cholesky factor of the flipped matrix into an upper one
_FLIP = np.eye(3)[::-1]


def pseudo_inertia(params10: ArrayLike) -> FloatArray:
    """Pseudo-inertia ``J = [[tr(I)/2 E - I, h], [h^T, m]]`` (..., 4, 4), kg m^2, of params10 (..., 10)."""
    p = np.asarray(params10, dtype=float)
    inertia = inertia_matrix_from_entries(p[..., 4:10])
    out = np.empty((*p.shape[:-1], 4, 4))
    out[..., :3, :3] = 0.5 * np.trace(inertia, axis1=-2, axis2=-1)[..., None, None] * np.eye(3) - inertia
    out[..., :3, 3] = p[..., 1:4]
    out[..., 3, :3] = p[..., 1:4]
    out[..., 3, 3] = p[..., 0]
    return out


def params10_from_pseudo_inertia(pseudo: ArrayLike) -> FloatArray:
    """Inverse of :func:`pseudo_inertia`: params10 (..., 10) of a symmetric ``J`` (..., 4, 4); ``I = tr(Sigma) E - Sigma``."""
    j = np.asarray(pseudo, dtype=float)
    sigma = j[..., :3, :3]
    inertia = np.trace(sigma, axis1=-2, axis2=-1)[..., None, None] * np.eye(3) - sigma
    entries = np.stack([inertia[..., r, c] for r, c in _ENTRIES], axis=-1)
    return np.concatenate((j[..., 3:4, 3], j[..., :3, 3], entries), axis=-1)


def is_physically_consistent(params10: ArrayLike, rtol: float = 1e-12) -> bool:
    """Whether one body's params10 (10,) is physically consistent: ``m > 0`` and ``J`` positive definite.

    ``J``'s smallest eigenvalue must exceed ``-rtol`` times its largest (a relative tolerance for rounding:
    with the default, a point mass or a rod, whose ``J`` is singular, passes). Non-finite values fail.
    """
    p = np.asarray(params10, dtype=float)
    if p.shape != (10,):
        raise SpaceIdInputError(f"params10: expected 10 numbers [m, mc (3), I (6)], got shape {p.shape}")
    if not np.all(np.isfinite(p)) or p[0] <= 0.0:
        return False
    eig = np.linalg.eigvalsh(pseudo_inertia(p))
    return bool(eig[0] >= -rtol * eig[-1])


def principal_moments_about_com(params10: ArrayLike) -> FloatArray:
    """Principal moments of inertia about the CoM (..., 3), ascending, kg m^2, of params10 (..., 10) with ``m > 0``.

    The classical route, independent of the pseudo-inertia: ``I_C = I - m S(c)^T S(c)`` (parallel axes, ``c = h / m``),
    then its eigenvalues.
    """
    p = np.asarray(params10, dtype=float)
    mass = p[..., 0]
    if np.any(~(mass > 0.0)):
        raise SpaceIdInputError("params10: principal moments about the CoM need a positive mass")
    com = p[..., 1:4] / mass[..., None]
    shift = np.sum(com * com, axis=-1)[..., None, None] * np.eye(3) - com[..., :, None] * com[..., None, :]
    inertia_com = inertia_matrix_from_entries(p[..., 4:10]) - mass[..., None, None] * shift
    return np.linalg.eigvalsh(inertia_com)


def satisfies_triangle_inequalities(params10: ArrayLike, rtol: float = 1e-12) -> bool:
    """The textbook test of one body's params10 (10,): ``m > 0``, principal moments about the CoM ``I_k >= 0`` and the
    triangle inequalities ``I_i + I_j >= I_k`` (each to ``rtol`` times the largest moment).

    Equivalent to :func:`is_physically_consistent` (the Schur complement of ``m`` in ``J`` is ``Sigma_C``, whose
    eigenvalues are ``(I_i + I_j - I_k) / 2``) but computed without the pseudo-inertia: the two are checks of each other.
    """
    p = np.asarray(params10, dtype=float)
    if p.shape != (10,):
        raise SpaceIdInputError(f"params10: expected 10 numbers [m, mc (3), I (6)], got shape {p.shape}")
    if not np.all(np.isfinite(p)) or p[0] <= 0.0:
        return False
    moments = principal_moments_about_com(p)
    slack = rtol * max(float(np.abs(moments).max()), np.finfo(float).tiny)
    return bool(moments[0] >= -slack and moments[0] + moments[1] >= moments[2] - slack)


def _log_cholesky_factor(z: FloatArray) -> FloatArray:
    """The upper-triangular factor ``U`` (..., 4, 4) of ``J = U U^T`` of log-Cholesky coordinates ``z`` (..., 10)."""
    upper = np.zeros((*z.shape[:-1], 4, 4))
    upper[..., 0, 0], upper[..., 1, 1], upper[..., 2, 2] = np.exp(z[..., 1]), np.exp(z[..., 2]), np.exp(z[..., 3])
    upper[..., 0, 1], upper[..., 1, 2], upper[..., 0, 2] = z[..., 4], z[..., 5], z[..., 6]
    upper[..., :3, 3] = z[..., 7:10]
    upper[..., 3, 3] = 1.0
    return upper * np.exp(z[..., 0])[..., None, None]


def log_cholesky_to_params10(z: ArrayLike) -> FloatArray:
    """params10 (..., 10) of log-Cholesky coordinates ``z`` (..., 10) (module docstring): always consistent."""
    upper = _log_cholesky_factor(np.asarray(z, dtype=float))
    return params10_from_pseudo_inertia(upper @ np.swapaxes(upper, -1, -2))


def params10_to_log_cholesky(params10: ArrayLike) -> FloatArray:
    """Log-Cholesky coordinates (..., 10) of consistent params10 (..., 10); inverse of :func:`log_cholesky_to_params10`.

    Raises :class:`SpaceIdInputError` if a body is not strictly consistent (``J`` not positive definite).
    """
    p = np.asarray(params10, dtype=float)
    if np.any(~np.isfinite(p)) or np.any(p[..., 0] <= 0.0):
        raise SpaceIdInputError("params10: log-Cholesky coordinates need finite values and a positive mass")
    mass = p[..., 0]
    com = p[..., 1:4] / mass[..., None]
    sigma = pseudo_inertia(p)[..., :3, :3]
    second_moment = sigma / mass[..., None, None] - com[..., :, None] * com[..., None, :]  # Sigma_c / m = A A^T
    try:
        lower = np.linalg.cholesky(_FLIP @ second_moment @ _FLIP)
    except np.linalg.LinAlgError:
        raise SpaceIdInputError(
            "params10: not physically consistent (pseudo-inertia not positive definite), no log-Cholesky coordinates"
        ) from None
    a = _FLIP @ lower @ _FLIP  # upper triangular, A A^T = Sigma_c / m
    diag = np.diagonal(a, axis1=-2, axis2=-1)
    return np.concatenate(
        (0.5 * np.log(mass)[..., None], np.log(diag), a[..., 0:1, 1], a[..., 1:2, 2], a[..., 0:1, 2], com), axis=-1
    )


def _index_array(name: str, value: ArrayLike, shape_tail: tuple[int, ...] = ()) -> IntArray:
    """``value`` as non-negative integer column indices of shape (n, *shape_tail), else :class:`SpaceIdInputError`."""
    array = np.asarray(value)
    if array.size == 0:
        return np.zeros((0, *shape_tail), dtype=np.intp)
    if not np.issubdtype(array.dtype, np.integer) or array.shape[1:] != shape_tail or np.any(array < 0):
        expected = "(n, " + ", ".join(map(str, shape_tail)) + ")" if shape_tail else "(n,)"
        raise SpaceIdInputError(f"{name}: expected non-negative integer column indices of shape {expected}, got {value!r}")
    return array.astype(np.intp)


@dataclass(frozen=True)
class PhysicalConsistency:
    """Which columns of a full parameter vector are rigid bodies and friction, and the consistent search box.

    The full parameter vector ``x`` (n_full,) holds each link's params10 (module conventions) in the
    columns ``link_columns[l]``, non-negative per-joint coefficients (friction, armature) in
    ``friction_columns`` and unconstrained ones (a torque offset) in ``free_columns``; every column is
    exactly one of these. An identification problem posed in **base parameters** gives
    ``base_map`` ``K`` (k, n_full) with ``theta = K x``; ``None`` means the problem's ``theta`` is ``x``.

    The consistent search moves ``s`` (n_full,): per link its log-Cholesky coordinates (in the link's
    columns), per friction column the coefficient itself. :meth:`search_box` bounds ``s`` in physical units:

    * ``alpha`` in ``[log(m_min), log(m_max)] / 2`` (``mass_range_kg[l]``);
    * CoM ``t`` in ``[-size, size]`` per axis (``size_m[l]``: a bound on the link's CoM offset from its frame
      origin and on its radii of gyration);
    * ``s12, s23, s13`` in ``[-size, size]``; ``d`` in ``[log(min_length_fraction * size), log(size)]``;
    * friction in ``[0, friction_upper]``: the consistent set is already a box there, so the coefficient is
      searched directly (zero, a common truth for small joints, stays reachable; ``exp``/softplus would
      exclude it);
    * free columns in ``[-free_bound, free_bound]`` (no physical constraint).

    Attributes:
        link_columns: (L, 10) column indices of each link's params10 in ``x``.
        friction_columns: (F,) column indices of friction coefficients (Coulomb N m, viscous N m s/rad).
        mass_range_kg: (L, 2) search range of each link's mass, 0 < low < high.
        size_m: (L,) link size (m), see above.
        friction_upper: (F,) largest friction coefficient searched, > 0.
        base_map: (k, n_full) ``K`` or ``None``.
        free_columns: (G,) column indices of unconstrained coefficients (default none).
        free_bound: (G,) half-width of their search range, > 0.
        min_length_fraction: smallest CoM spread searched, as a fraction of ``size_m`` (default 1e-3).
        nominal_full: (n_full,) prior values of the full parameters (e.g. the URDF's and zero friction), or ``None``
            (then :meth:`prior_full` builds one from the box); the ``sdp`` estimator regularises toward it.
    """

    link_columns: IntArray
    friction_columns: IntArray
    mass_range_kg: FloatArray
    size_m: FloatArray
    friction_upper: FloatArray
    base_map: FloatArray | None = None
    free_columns: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.intp))
    free_bound: FloatArray = field(default_factory=lambda: np.zeros(0))
    min_length_fraction: float = 1e-3
    nominal_full: FloatArray | None = None

    def __post_init__(self) -> None:
        links = _index_array("link_columns", self.link_columns, (10,))
        friction = _index_array("friction_columns", self.friction_columns)
        free = _index_array("free_columns", self.free_columns)
        n_links, n_friction = len(links), len(friction)
        free_bound = np.asarray(self.free_bound, dtype=float).reshape(-1)
        if free_bound.shape != (len(free),) or not np.all(np.isfinite(free_bound)) or np.any(free_bound <= 0.0):
            raise SpaceIdInputError(f"free_bound: expected {len(free)} positive half-widths, got {self.free_bound!r}")
        mass = np.asarray(self.mass_range_kg, dtype=float).reshape(-1, 2) if n_links else np.zeros((0, 2))
        size = np.asarray(self.size_m, dtype=float).reshape(-1)
        upper = np.asarray(self.friction_upper, dtype=float).reshape(-1)
        if (
            mass.shape != (n_links, 2)
            or not np.all(np.isfinite(mass))
            or np.any(mass[:, 0] <= 0.0)
            or np.any(mass[:, 1] <= mass[:, 0])
        ):
            raise SpaceIdInputError(f"mass_range_kg: expected {n_links} pairs 0 < low < high (kg), got {self.mass_range_kg!r}")
        if size.shape != (n_links,) or not np.all(np.isfinite(size)) or np.any(size <= 0.0):
            raise SpaceIdInputError(f"size_m: expected {n_links} positive lengths (m), got {self.size_m!r}")
        if upper.shape != (n_friction,) or not np.all(np.isfinite(upper)) or np.any(upper <= 0.0):
            raise SpaceIdInputError(f"friction_upper: expected {n_friction} positive coefficients, got {self.friction_upper!r}")
        if not 0.0 < self.min_length_fraction < 1.0:
            raise SpaceIdInputError(f"min_length_fraction: expected a number in (0, 1), got {self.min_length_fraction!r}")
        columns = np.concatenate((links.ravel(), friction, free))
        n_full = len(columns)
        if n_full == 0 or not np.array_equal(np.sort(columns), np.arange(n_full)):
            raise SpaceIdInputError(
                f"link_columns, friction_columns and free_columns: each column 0..{n_full - 1} of the full parameters must appear exactly once"
            )
        base_map = None
        if self.base_map is not None:
            base_map = np.asarray(self.base_map, dtype=float)
            if base_map.ndim != 2 or base_map.shape[1] != n_full or not np.all(np.isfinite(base_map)):
                raise SpaceIdInputError(f"base_map: expected a finite (k, {n_full}) matrix, got shape {np.shape(self.base_map)}")
        nominal = None
        if self.nominal_full is not None:
            nominal = np.asarray(self.nominal_full, dtype=float)
            if nominal.shape != (n_full,) or not np.all(np.isfinite(nominal)):
                raise SpaceIdInputError(f"nominal_full: expected {n_full} finite values, got shape {np.shape(self.nominal_full)}")
        for attr, value in (
            ("nominal_full", nominal),
            ("link_columns", links),
            ("friction_columns", friction),
            ("mass_range_kg", mass),
            ("size_m", size),
            ("friction_upper", upper),
            ("base_map", base_map),
            ("free_columns", free),
            ("free_bound", free_bound),
        ):
            object.__setattr__(self, attr, value)

    @classmethod
    def per_joint(
        cls,
        n_links: int,
        *,
        mass_range_kg: Sequence[float] | FloatArray,
        size_m: float | Sequence[float],
        friction_upper: Sequence[float] | FloatArray = (),
        base_map: FloatArray | None = None,
    ) -> PhysicalConsistency:
        """The layout of the source's ``p_dyn``: per joint its link's params10 then its friction coefficients.

        ``friction_upper`` holds the bounds of one joint's friction coefficients (e.g. ``(fc_max, fv_max)``, the
        same for every joint, or ``()`` for no friction columns); ``mass_range_kg`` one ``(low, high)`` pair for
        all links or one per link; ``size_m`` one length or one per link.
        """
        per = np.asarray(friction_upper, dtype=float).reshape(-1)
        stride = 10 + len(per)
        starts = stride * np.arange(n_links)
        mass = np.broadcast_to(np.asarray(mass_range_kg, dtype=float), (n_links, 2))
        return cls(
            link_columns=starts[:, None] + np.arange(10),
            friction_columns=(starts[:, None] + 10 + np.arange(len(per))).ravel(),
            mass_range_kg=mass,
            size_m=np.broadcast_to(np.asarray(size_m, dtype=float), (n_links,)),
            friction_upper=np.tile(per, n_links),
            base_map=base_map,
        )

    @property
    def n_links(self) -> int:
        """L."""
        return len(self.link_columns)

    @property
    def n_full(self) -> int:
        """Columns of the full parameter vector (= dimension of the consistent search)."""
        return 10 * self.n_links + len(self.friction_columns) + len(self.free_columns)

    @property
    def n_theta(self) -> int:
        """Length of the problem's ``theta``: rows of ``base_map``, else ``n_full``."""
        return self.n_full if self.base_map is None else self.base_map.shape[0]

    def search_box(self) -> tuple[FloatArray, FloatArray]:
        """Bounds ``(lower, upper)`` (n_full,) of the consistent search coordinates (class docstring)."""
        size = self.size_m[:, None]
        log_size = np.log(self.size_m)[:, None]
        lower_links = np.hstack(
            (
                0.5 * np.log(self.mass_range_kg[:, :1]),
                np.repeat(log_size + np.log(self.min_length_fraction), 3, axis=1),
                -np.repeat(size, 6, axis=1),
            )
        )
        upper_links = np.hstack(
            (0.5 * np.log(self.mass_range_kg[:, 1:]), np.repeat(log_size, 3, axis=1), np.repeat(size, 6, axis=1))
        )
        lower, upper = np.empty(self.n_full), np.empty(self.n_full)
        lower[self.link_columns], upper[self.link_columns] = lower_links, upper_links
        lower[self.friction_columns], upper[self.friction_columns] = 0.0, self.friction_upper
        lower[self.free_columns], upper[self.free_columns] = -self.free_bound, self.free_bound
        return lower, upper

    def link_scale(self) -> tuple[FloatArray, FloatArray]:
        """Per link a typical mass (L,) kg, the geometric mean of its mass range, and its size (L,) m."""
        return np.sqrt(self.mass_range_kg[:, 0] * self.mass_range_kg[:, 1]), self.size_m

    def parameter_scale(self) -> FloatArray:
        """A typical magnitude (n_full,) of each full parameter, in its unit: per link with typical mass ``m`` and size
        ``s`` (:meth:`link_scale`) ``m`` (kg), ``m s`` (kg m) for the first moments, ``m s^2`` (kg m^2) for the inertia;
        a friction column its search bound ``friction_upper``; a free column its ``free_bound``."""
        mass, size = self.link_scale()
        scale = np.empty(self.n_full)
        scale[self.link_columns] = mass[:, None] * size[:, None] ** np.array([0, 1, 1, 1, 2, 2, 2, 2, 2, 2])
        scale[self.friction_columns] = self.friction_upper
        scale[self.free_columns] = self.free_bound
        return scale

    def prior_full(self) -> FloatArray:
        """The full parameters (n_full,) a regulariser pulls toward: ``nominal_full`` when given, else per link a uniform
        solid sphere of the link's typical mass and diameter ``size`` centred on its frame origin, zero friction and
        free coefficients (physically consistent, but only a placeholder for missing prior knowledge)."""
        if self.nominal_full is not None:
            return self.nominal_full.copy()
        mass, size = self.link_scale()
        moment = 0.4 * mass * (size / 2.0) ** 2  # solid sphere, kg m^2
        prior = np.zeros(self.n_full)
        zero = np.zeros_like(mass)
        prior[self.link_columns] = np.stack([mass, zero, zero, zero, moment, zero, moment, zero, zero, moment], axis=1)
        return prior

    def link_congruence(self) -> FloatArray:
        """Per link the diagonal (L, 4) of ``T = sqrt(m) diag(s, s, s, 1)`` (``m``, ``s`` of :meth:`link_scale`): the
        pseudo-inertia in scaled form is ``J_hat = T^-1 J T^-1``, of order one for a body of the link's size, and
        ``J_hat >= 0`` exactly when ``J >= 0`` (a congruence)."""
        mass, size = self.link_scale()
        return np.sqrt(mass)[:, None] * np.stack([size, size, size, np.ones_like(size)], axis=1)

    @cached_property
    def _scaled_pseudo_inertia_map(self) -> FloatArray:
        basis = np.eye(16).reshape(16, 4, 4)
        symmetric = 0.5 * (basis + np.swapaxes(basis, -1, -2))
        t = self.link_congruence()[:, None, :]  # (L, 1, 4)
        scaled = t[..., :, None] * symmetric[None] * t[..., None, :]  # (L, 16, 4, 4): T E T
        out = np.swapaxes(params10_from_pseudo_inertia(scaled), -1, -2).reshape(self.n_links, 10, 4, 4)
        out.flags.writeable = False
        return out

    def scaled_pseudo_inertia_map(self) -> FloatArray:
        """``M`` (L, 10, 4, 4), symmetric in its last two axes: a link's params10 is ``sum_ij M[l, :, i, j] J_hat[i, j]``
        for a symmetric scaled pseudo-inertia ``J_hat`` (:meth:`link_congruence`); linear, from
        :func:`params10_from_pseudo_inertia` (computed once, read-only)."""
        return self._scaled_pseudo_inertia_map

    # ------------------------------------------------------------------ factor coordinates (local descent)
    @property
    def factor_dimension(self) -> int:
        """Length of the factor coordinates: 16 per link, one per friction and free column."""
        return 16 * self.n_links + len(self.friction_columns) + len(self.free_columns)

    def _factor_parts(self, factor: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Split factor coordinates (D,) into the links' ``Y_hat`` (L, 4, 4), friction roots (F,) and free values (G,)."""
        y = np.asarray(factor, dtype=float)
        if y.shape != (self.factor_dimension,):
            raise SpaceIdInputError(f"factor: expected {self.factor_dimension} factor coordinates, got shape {y.shape}")
        n_links, n_friction = self.n_links, len(self.friction_columns)
        start = 16 * n_links
        return y[:start].reshape(n_links, 4, 4), y[start : start + n_friction], y[start + n_friction :]

    def factor_from_search(self, search: ArrayLike, root_floor: float = 0.0) -> FloatArray:
        """Factor coordinates (D,) of one point (n_full,) of the consistent search coordinates; friction roots ``w`` below
        ``root_floor`` are raised to it (``w = 0`` is a stationary point of ``scale w^2`` that a descent cannot leave).

        Factor coordinates (a Burer-Monteiro factorisation): per link a full 4x4 ``Y_hat`` with ``J_hat = Y_hat Y_hat^T``
        (here the log-Cholesky factor, scaled), per friction column ``w`` with coefficient ``scale w^2``, per free column
        the value over its scale (:meth:`parameter_scale`). Every real vector is a consistent set of bodies, the
        boundary (a thin body, zero friction) is at finite coordinates, and the maps are polynomials: for a convex cost
        every local minimum in these coordinates is a global minimum over the consistent parameters (Journée, Bach,
        Absil and Sepulchre 2010: a local minimum of ``f(Y Y^T)`` with square ``Y`` is global when ``f`` is convex).
        """
        s = np.asarray(search, dtype=float)
        scale = self.parameter_scale()
        factor = _log_cholesky_factor(s[self.link_columns]) / self.link_congruence()[:, :, None]  # T^-1 U
        friction = np.maximum(np.sqrt(np.clip(s[self.friction_columns], 0.0, None) / scale[self.friction_columns]), root_floor)
        return np.concatenate((factor.reshape(-1), friction, s[self.free_columns] / scale[self.free_columns]))

    def full_from_factor(self, factor: ArrayLike) -> FloatArray:
        """Full parameters (n_full,) of factor coordinates (D,) (:meth:`factor_from_search`): always consistent."""
        y_hat, roots, free = self._factor_parts(np.asarray(factor, dtype=float))
        scale = self.parameter_scale()
        full = np.empty(self.n_full)
        full[self.link_columns] = np.einsum("lcij,lij->lc", self.scaled_pseudo_inertia_map(), y_hat @ np.swapaxes(y_hat, -1, -2))
        full[self.friction_columns] = scale[self.friction_columns] * roots**2
        full[self.free_columns] = scale[self.free_columns] * free
        return full

    def factor_jacobian(self, factor: ArrayLike) -> FloatArray:
        """``d full / d factor`` (n_full, D) at factor coordinates (D,): ``d params10_c / d Y_hat_ab = 2 sum_j M[c, a, j]
        Y_hat[j, b]`` per link, ``2 scale w`` per friction column, ``scale`` per free column."""
        y_hat, roots, _ = self._factor_parts(np.asarray(factor, dtype=float))
        scale = self.parameter_scale()
        out = np.zeros((self.n_full, self.factor_dimension))
        blocks = 2.0 * self.scaled_pseudo_inertia_map() @ y_hat[:, None, :, :]  # (L, 10, 4, 4)
        for link, columns in enumerate(self.link_columns):
            out[columns, 16 * link : 16 * link + 16] = blocks[link].reshape(10, 16)
        start = 16 * self.n_links
        n_friction, n_free = len(self.friction_columns), len(self.free_columns)
        out[self.friction_columns, start + np.arange(n_friction)] = 2.0 * scale[self.friction_columns] * roots
        out[self.free_columns, start + n_friction + np.arange(n_free)] = scale[self.free_columns]
        return out

    def factor_curvature(self, weights: ArrayLike) -> FloatArray:
        """The Hessian (D, D) of ``weights . full(factor)`` for weights (n_full,): constant, the maps being quadratic;
        per link ``2 G kron E`` with ``G = sum_c weights_c M[c]``, per friction column ``2 scale weights_c``."""
        w = np.asarray(weights, dtype=float)
        out = np.zeros((self.factor_dimension, self.factor_dimension))
        gram = np.einsum("lc,lcij->lij", w[self.link_columns], self.scaled_pseudo_inertia_map())
        for link in range(self.n_links):
            out[16 * link : 16 * link + 16, 16 * link : 16 * link + 16] = 2.0 * np.kron(gram[link], np.eye(4))
        friction = 16 * self.n_links + np.arange(len(self.friction_columns))
        out[friction, friction] = 2.0 * self.parameter_scale()[self.friction_columns] * w[self.friction_columns]
        return out

    def full_from_search(self, search: ArrayLike) -> FloatArray:
        """Full parameters (..., n_full) of consistent search coordinates (..., n_full): every body consistent."""
        s = np.asarray(search, dtype=float)
        full = s.copy()
        full[..., self.link_columns] = log_cholesky_to_params10(s[..., self.link_columns])
        return full

    def search_from_full(self, full: ArrayLike) -> FloatArray:
        """Inverse of :meth:`full_from_search` (every body strictly consistent, else :class:`SpaceIdInputError`)."""
        x = np.asarray(full, dtype=float)
        s = x.copy()
        s[..., self.link_columns] = params10_to_log_cholesky(x[..., self.link_columns])
        return s

    def theta_from_full(self, full: ArrayLike) -> FloatArray:
        """The problem's ``theta`` (..., n_theta) of full parameters (..., n_full): ``K x``, or ``x``."""
        x = np.asarray(full, dtype=float)
        return x if self.base_map is None else x @ self.base_map.T

    def links_consistent(self, full: ArrayLike, rtol: float = 1e-12) -> list[bool]:
        """Per link, whether its params10 in ``full`` (n_full,) is physically consistent (:func:`is_physically_consistent`)."""
        x = np.asarray(full, dtype=float)
        return [is_physically_consistent(x[cols], rtol) for cols in self.link_columns]

    def friction_consistent(self, full: ArrayLike) -> bool:
        """Whether every friction coefficient in ``full`` (n_full,) is >= 0."""
        return bool(np.all(np.asarray(full, dtype=float)[self.friction_columns] >= 0.0))
