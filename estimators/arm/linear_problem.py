"""Linear-in-parameters identification: ``tau = Y theta + noise``, the fixed-base arm's problem.

:class:`LinearIdentificationProblem` is the counterpart of :class:`~estimators.problem.IdentificationProblem`
for a model that is linear in its unknowns (joint torques of a fixed-base arm from the regressor
``Y(q, dq, ddq)``, with friction columns), duck-typed so that every :class:`~estimators.base.Estimator`
fits it with ``fit_problem``:

* rows: the N measured values (e.g. T samples x n joints, flattened sample-major); ``Y`` (N, k), ``tau`` (N,)
  (N m for torques); ``row_group`` (N,) says which group (joint) each row belongs to;
* ``cost(theta)`` (P, k) -> (P,): the weighted mean squared residual ``mean_i w_i (Y_i theta - tau_i)^2``
  with row weights ``w_i = 1 / row_std_i^2`` normalised to mean 1 (so the cost stays in (N m)^2 and is the
  plain mean squared residual when every row has the same std; without ``row_std`` all weights are 1).
  This is the source's fitness ``sum_n k_n sum_i (tau_ni - tau_pred_ni)^2`` with joint weights
  ``k_n = 1 / sigma_n^2``: for Gaussian noise its minimum is the maximum-likelihood estimate;
* budget: one evaluation of one ``theta`` over all N rows counts N model samples, so
  ``n_evaluations = n_model_samples / N`` counts whole-objective evaluations as for the free-floating problem.
  Over all rows the cost is computed from the Gram matrix ``Y^T W Y`` (k x k, precomputed): ``O(P k^2)``
  instead of ``O(P N k)``, the same value up to rounding (a test holds the two to 1e-9 relative), counted
  the same;
* ``fisher``/``crlb_std``: for white noise with per-row std ``s_i`` the Fisher information is
  ``Y^T diag(1/s^2) Y`` (exact: the model is linear). ``s`` is ``row_std`` when given, else estimated per
  group from the residual at the estimate, ``s_g^2 = RSS_g / (N_g - k N_g / N)`` (the ``k`` degrees of
  freedom shared among the groups in proportion to their rows);
* identifiability as in :mod:`estimators.problem`: a parameter whose Cramér-Rao std exceeds
  ``IDENTIFIABLE_FRACTION`` of its search range, or that has a component in a direction the data do not
  inform (a rank-deficient ``Y``, e.g. full rather than base parameters), is reported as not identifiable.

The search range (``lower``, ``upper``) bounds the metaheuristics; least squares ignores it.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from estimators.arm.consistency import PhysicalConsistency
from estimators.estimate import Estimate
from estimators.parameters import Parameterisation
from estimators.problem import IdentificationProblem, Samples, identifiability
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.information import cramer_rao_std

IntArray = NDArray[np.intp]


class LinearParameters(Parameterisation):
    """Names, nominal values and search range of the k unknowns of a linear problem (no momentum-model map).

    Args:
        names: the k parameter names (unique, with units).
        nominal, lower, upper: (k,) each; nominal inside the range.
        name: what the estimate calls the parameterisation (default ``"linear"``, e.g. ``"base"``).
    """

    def __init__(
        self, names: Sequence[str], nominal: FloatArray, lower: FloatArray, upper: FloatArray, name: str = "linear"
    ) -> None:
        names = tuple(names)
        if not names or not all(isinstance(n, str) and n for n in names) or len(set(names)) != len(names):
            raise SpaceIdInputError(f"names: expected unique non-empty parameter names, got {names!r}")
        self.name = name
        self.names = names
        super().__init__(nominal, lower, upper)

    def composite(self, theta: FloatArray) -> tuple[FloatArray, FloatArray | None]:
        """Not defined: linear parameters do not describe a free-floating base or payload."""
        raise SpaceIdInputError(
            f"{self.name} parameters are linear-model unknowns; use LinearIdentificationProblem, not IdentificationModel"
        )

    def composite_jacobian(self, theta: FloatArray) -> tuple[FloatArray, FloatArray | None]:
        """Not defined (see :meth:`composite`)."""
        return self.composite(theta)

    def physical(self, theta: FloatArray) -> dict[str, Any]:
        """No derived quantities: the parameters are the quantities."""
        return {}


def _matrix(name: str, value: ArrayLike, shape: tuple[int | None, ...], what: str) -> FloatArray:
    """``value`` as a finite float array of ``shape`` (``None`` = any length), else :class:`SpaceIdInputError`."""
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise SpaceIdInputError(f"{name}: expected {what}, got {type(value).__name__}") from None
    if array.ndim != len(shape) or any(s is not None and s != a for s, a in zip(shape, array.shape, strict=True)):
        raise SpaceIdInputError(f"{name}: expected {what}, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise SpaceIdInputError(f"{name}: expected {what}; it holds NaN or inf at {np.argwhere(~np.isfinite(array))[0].tolist()}")
    return array


def image_box(k_map: FloatArray, lower: FloatArray, upper: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The smallest box holding ``K x`` for every ``x`` in ``[lower, upper]``: (r,) x 2 (interval arithmetic).

    The search box of base parameters ``beta = K p`` whose full parameters ``p`` lie in a box.
    """
    positive, negative = np.clip(k_map, 0.0, None), np.clip(k_map, None, 0.0)
    return positive @ lower + negative @ upper, positive @ upper + negative @ lower


class LinearIdentificationProblem:
    """The objective ``tau = Y theta`` on one data set; see the module docstring.

    Args:
        Y: regressor (N, k).
        tau: measurements (N,) (N m for joint torques).
        names: the k parameter names.
        lower, upper: search range (k,) of the metaheuristics.
        nominal: value assumed without identification (k,), inside the range; default the range's middle.
        row_std: noise std of each row (N,), > 0, when known; ``None`` estimates it per group from residuals.
        row_group: group of each row (N,) non-negative ints (e.g. the joint index), for per-group noise; default one group.
        consistency: which columns are links and friction (:class:`~estimators.arm.consistency.PhysicalConsistency`),
            for the physically consistent estimators and the consistency report; its ``n_theta`` must be k.
        name: the parameterisation's name in the estimate (default ``"linear"``).

    Attributes:
        parameters: :class:`LinearParameters`; Y, tau, row_std, row_group, consistency as given
        (``row_group`` renumbered 0..G-1, original labels in ``group_labels``); weights (N,): the cost's row weights.
        n_samples: N rows; n_model_samples: rows evaluated so far (the budget counter).
    """

    def __init__(
        self,
        Y: ArrayLike,
        tau: ArrayLike,
        names: Sequence[str],
        lower: ArrayLike,
        upper: ArrayLike,
        nominal: ArrayLike | None = None,
        row_std: ArrayLike | None = None,
        row_group: ArrayLike | None = None,
        consistency: PhysicalConsistency | None = None,
        name: str = "linear",
    ) -> None:
        self.Y = np.ascontiguousarray(_matrix("Y", Y, (None, None), "a finite regressor matrix (N rows, k parameters)"))
        n_rows, k = self.Y.shape
        if n_rows == 0 or k == 0:
            raise SpaceIdInputError(f"Y: expected at least one row and one column, got shape {self.Y.shape}")
        self.tau = _matrix("tau", tau, (n_rows,), f"{n_rows} finite measurements (one per row of Y)")
        lower_v = _matrix("lower", lower, (k,), f"{k} finite lower bounds")
        upper_v = _matrix("upper", upper, (k,), f"{k} finite upper bounds")
        nominal_v = (
            0.5 * (lower_v + upper_v) if nominal is None else _matrix("nominal", nominal, (k,), f"{k} finite nominal values")
        )
        if len(tuple(names)) != k:
            raise SpaceIdInputError(f"names: expected {k} names (one per column of Y), got {len(tuple(names))}")
        self.parameters = LinearParameters(names, nominal_v, lower_v, upper_v, name)
        self.row_std: FloatArray | None = None
        if row_std is not None:
            self.row_std = _matrix("row_std", row_std, (n_rows,), f"{n_rows} noise standard deviations (one per row)")
            if np.any(self.row_std <= 0.0):
                raise SpaceIdInputError("row_std: expected positive noise standard deviations")
        groups = np.zeros(n_rows, dtype=np.intp) if row_group is None else np.asarray(row_group)
        if groups.shape != (n_rows,) or not np.issubdtype(groups.dtype, np.integer) or np.any(groups < 0):
            raise SpaceIdInputError(f"row_group: expected {n_rows} non-negative integers (e.g. the joint of each row)")
        self.group_labels, self.row_group = np.unique(groups, return_inverse=True)
        if consistency is not None and consistency.n_theta != k:
            raise SpaceIdInputError(f"consistency: describes {consistency.n_theta} parameters, Y has {k} columns")
        self.consistency = consistency
        self.n_samples = n_rows
        self.n_model_samples = 0
        inverse_variance = np.ones(n_rows) if self.row_std is None else 1.0 / self.row_std**2
        self.weights = inverse_variance / inverse_variance.mean()
        # Gram form of the whole-data cost about the nominal (smaller residuals, less cancellation)
        weighted_y = self.Y * self.weights[:, None]
        residual0 = self.Y @ nominal_v - self.tau
        self._gram = (weighted_y.T @ self.Y) / n_rows
        self._gradient0 = (weighted_y.T @ residual0) / n_rows
        self._cost0 = float(self.weights @ residual0**2) / n_rows
        self._root: tuple[FloatArray, FloatArray] | None = None

    def with_row_std(self, row_std: ArrayLike) -> LinearIdentificationProblem:
        """The same data and parameters with the per-row noise std ``row_std`` (N,) (e.g. the per-joint std WLS
        estimated): its cost is the weighted one, its bound uses ``row_std``."""
        params = self.parameters
        return LinearIdentificationProblem(
            self.Y,
            self.tau,
            params.names,
            params.lower,
            params.upper,
            params.nominal,
            row_std=row_std,
            row_group=self.group_labels[self.row_group],
            consistency=self.consistency,
            name=params.name,
        )

    # ------------------------------------------------------------------ shared with IdentificationProblem
    n_params = IdentificationProblem.n_params
    n_evaluations = IdentificationProblem.n_evaluations
    subsets = IdentificationProblem.subsets
    cost_on_subsets = IdentificationProblem.cost_on_subsets

    @property
    def n_groups(self) -> int:
        """G, the number of row groups."""
        return len(self.group_labels)

    # ------------------------------------------------------------------ objective
    def predict(self, theta: FloatArray, samples: Samples = slice(None), count: bool = True) -> FloatArray:
        """Predicted measurements (P, N') of ``theta`` (P, k) on the rows ``samples``; counted unless ``count=False``."""
        theta = np.atleast_2d(np.asarray(theta, dtype=float))
        out = theta @ self.Y[samples].T
        if count:
            self.n_model_samples += out.size
        return out

    def cost(self, theta: FloatArray, samples: Samples = slice(None), count: bool = True) -> FloatArray:
        """Weighted mean squared residual (N m)^2 (module docstring) over the rows ``samples``, of ``theta`` (P, k): (P,)."""
        theta = np.atleast_2d(np.asarray(theta, dtype=float))
        if isinstance(samples, slice) and samples == slice(None):
            delta = theta - self.parameters.nominal
            if count:
                self.n_model_samples += len(theta) * self.n_samples
            quadratic = np.einsum("pi,pi->p", delta @ self._gram, delta)
            return np.maximum(self._cost0 + 2.0 * delta @ self._gradient0 + quadratic, 0.0)
        error = self.predict(theta, samples, count) - self.tau[samples]
        return np.mean(self.weights[samples] * error * error, axis=1)

    def root_form(self) -> tuple[FloatArray, FloatArray]:
        """``(A, theta_ls)``: ``A`` (m, k), ``theta_ls`` (k,) with ``|A (theta - theta_ls)|^2 = cost(theta) - min cost`` for every
        ``theta``: ``A = Lambda^(1/2) V^T`` from the eigen-decomposition ``V Lambda V^T`` of the (normalised) weighted Gram
        matrix (the m eigenvalues above 1e-14 of the largest), ``theta_ls`` its least-squares minimiser (minimum-norm step
        from the nominal when ``Y`` is rank deficient). A k-row least-squares form of the N-row cost for local polishing."""
        if self._root is None:
            eigenvalues, vectors = np.linalg.eigh(self._gram)
            keep = eigenvalues > eigenvalues.max() * 1e-14
            shift = -(vectors[:, keep] / eigenvalues[keep]) @ (vectors[:, keep].T @ self._gradient0)
            self._root = (np.sqrt(eigenvalues[keep])[:, None] * vectors[:, keep].T, self.parameters.nominal + shift)
        return self._root

    def root_cost(self, theta: FloatArray, count: bool = True) -> FloatArray:
        """``A (theta - theta_ls)`` (m,) of :meth:`root_form` for one ``theta`` (k,); counted as one evaluation."""
        if count:
            self.n_model_samples += self.n_samples
        matrix, minimiser = self.root_form()
        return matrix @ (np.asarray(theta, dtype=float) - minimiser)

    def residuals(self, theta: FloatArray, count: bool = True) -> FloatArray:
        """``Y theta - tau`` (N,) at one ``theta`` (k,), unweighted (N m)."""
        return self.predict(theta, count=count)[0] - self.tau

    def jacobian(self, theta: FloatArray | None = None, count: bool = True) -> FloatArray:
        """``d predicted / d theta`` = ``Y`` (N, k) (any ``theta``); counted as k evaluations like the nonlinear problem's."""
        if count:
            self.n_model_samples += self.n_params * self.n_samples
        return self.Y

    # ------------------------------------------------------------------ noise, information
    def group_noise_std(self, theta: FloatArray) -> FloatArray:
        """Per-group noise std (G,) estimated from the residual at ``theta`` (k,): ``sqrt(RSS_g / (N_g - k N_g / N))``."""
        residual = self.residuals(theta, count=False)
        rss = np.bincount(self.row_group, weights=residual**2, minlength=self.n_groups)
        rows = np.bincount(self.row_group, minlength=self.n_groups).astype(float)
        dof = np.maximum(rows * (1.0 - self.n_params / self.n_samples), 1.0)
        return np.sqrt(rss / dof)

    def noise_std(self, theta: FloatArray) -> tuple[FloatArray, str]:
        """Per-row noise std (N,) for the bound and its source: ``"given"`` (``row_std``) or ``"residual"`` (per group)."""
        if self.row_std is not None:
            return self.row_std, "given"
        return self.group_noise_std(theta)[self.row_group], "residual"

    def fisher(self, theta: FloatArray, row_std: FloatArray | None = None) -> FloatArray:
        """Fisher information ``Y^T diag(1 / s^2) Y`` (k, k); ``s`` = ``row_std`` or :meth:`noise_std` at ``theta``."""
        s = self.noise_std(theta)[0] if row_std is None else np.asarray(row_std, dtype=float)
        weighted = self.Y / s[:, None]
        return weighted.T @ weighted

    def crlb_std(self, theta: FloatArray, row_std: FloatArray | None = None) -> FloatArray:
        """Cramér-Rao standard deviations (k,); ``inf`` for parameters in directions the data do not inform."""
        width = self.parameters.width
        return cramer_rao_std(self.fisher(theta, row_std) * np.outer(width, width)) * width

    # ------------------------------------------------------------------ result
    def make_estimate(
        self,
        theta: FloatArray,
        *,
        estimator: str,
        options: dict[str, Any],
        seed: int | None,
        cost_history: FloatArray | list[float],
        wall_time_s: float,
        extra: dict[str, Any] | None = None,
    ) -> Estimate:
        """Wrap ``theta`` (k,) as an :class:`~estimators.estimate.Estimate`.

        ``theta_std`` is the Cramér-Rao bound; ``noise_std_rad_s`` holds the RMS over rows of the noise std used
        (N m here, the field keeps the free-floating problem's name). ``physical``: per group (``group_labels``)
        the residual RMS and noise std (N m); with a :attr:`consistency` and full parameters (``theta`` itself,
        or ``extra["full_params"]`` from an estimator that searched them) also each link's mass and whether
        each link and the friction are physically consistent.
        """
        theta = np.asarray(theta, dtype=float).copy()
        params = self.parameters
        extra = dict(extra or {})
        row_std, source = self.noise_std(theta)
        std = self.crlb_std(theta, row_std)
        identifiable, messages = identifiability(params.names, std, params.width, "data")
        residual = self.residuals(theta, count=False)
        rows = np.bincount(self.row_group, minlength=self.n_groups)
        physical: dict[str, Any] = {
            "group_labels": self.group_labels.tolist(),
            "residual_rms_per_group": np.sqrt(np.bincount(self.row_group, weights=residual**2, minlength=self.n_groups) / rows),
            "noise_std_per_group": np.sqrt(np.bincount(self.row_group, weights=row_std**2, minlength=self.n_groups) / rows),
        }
        if self.consistency is not None:
            full = np.asarray(extra["full_params"], dtype=float) if "full_params" in extra else None
            if full is None and self.consistency.base_map is None:
                full = theta
            if full is not None:
                physical.update(
                    link_mass_kg=full[self.consistency.link_columns[:, 0]],
                    links_physically_consistent=self.consistency.links_consistent(full),
                    friction_non_negative=self.consistency.friction_consistent(full),
                )
        return Estimate.of_problem(
            self,
            theta,
            estimator=estimator,
            options=options,
            seed=seed,
            cost_history=cost_history,
            wall_time_s=wall_time_s,
            extra=extra,
            theta_std=std,
            identifiable=identifiable,
            insufficient_excitation=messages,
            physical=physical,
            physical_std={},
            noise_std_rad_s=float(np.sqrt(np.mean(row_std**2))),
            noise_source=source,
        )
