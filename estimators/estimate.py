"""The result of an identification: parameters, their Cramér-Rao standard deviations, and how it was found.

The estimate file (``spaceid identify --out``) uses the keys of ``truth.json`` where they mean the
same thing (``base_mass_kg``, ``base_com_m``, ``base_inertia_kgm2``, ``fuel_consumed_kg``,
``tank_position_m``), each with a ``..._std`` partner, so estimate and truth compare key by key.
A quantity the log does not inform is ``null`` and named in ``insufficient_excitation``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spaceid_gym.arrays import FloatArray
from spaceid_gym.files import jsonable, write_json_atomic


@dataclass
class Estimate:
    """An identified parameter set (see the module docstring for the file form).

    Attributes:
        estimator: registry name of the estimator; ``options`` its constructor options; ``seed``.
        parameterisation: ``fuel``, ``base`` or ``payload``; ``names`` the k unknowns.
        theta: the estimate (k,); ``theta_std``: Cramér-Rao standard deviations at it (k,),
            ``inf`` where the log does not inform the parameter.
        identifiable: (k,) bool; ``insufficient_excitation``: one message per parameter that is not.
        physical / physical_std: derived quantities (mass, CoM, inertia, ...) and their standard
            deviations (delta method); ``None`` where not identifiable.
        cost: final mean squared residual over the whole log, (rad/s)^2.
        noise_std_rad_s: the gyro noise used for the bound; ``noise_source``: ``"given"`` or
            ``"residual"`` (estimated from the final residual).
        cost_history: best full-log cost after each iteration/generation, (rad/s)^2.
        n_evaluations: objective evaluations used, in whole-log equivalents (model samples / T).
        n_model_samples: model evaluations of single samples (particles x samples, summed).
        wall_time_s: time of the fit (including the per-log model set-up).
        n_samples: samples in the log.
    """

    estimator: str
    options: dict[str, Any]
    seed: int | None
    parameterisation: str
    names: tuple[str, ...]
    theta: FloatArray
    theta_std: FloatArray
    identifiable: NDArray[np.bool_]
    insufficient_excitation: list[str]
    physical: dict[str, Any]
    physical_std: dict[str, Any]
    cost: float
    noise_std_rad_s: float
    noise_source: str
    cost_history: FloatArray
    n_evaluations: float
    n_model_samples: int
    wall_time_s: float
    n_samples: int
    extra: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def of_problem(
        cls,
        problem: Any,
        theta: FloatArray,
        *,
        estimator: str,
        options: dict[str, Any],
        seed: int | None,
        cost_history: FloatArray | list[float],
        wall_time_s: float,
        extra: dict[str, Any] | None,
        **assessment: Any,
    ) -> Estimate:
        """The estimate of ``theta`` (k,) on ``problem`` (an identification problem: parameters, cost, counters), with the
        run's facts and the problem's ``assessment`` of it (``theta_std``, ``identifiable``, ``insufficient_excitation``,
        ``physical``, ``physical_std``, ``noise_std_rad_s``, ``noise_source``): what every problem's ``make_estimate``
        shares."""
        params = problem.parameters
        return cls(
            estimator=estimator,
            options=options,
            seed=seed,
            parameterisation=params.name,
            names=tuple(params.names),
            theta=theta,
            cost=float(problem.cost(theta, count=False)[0]),
            cost_history=np.asarray(cost_history, dtype=float),
            n_evaluations=problem.n_evaluations,
            n_model_samples=problem.n_model_samples,
            wall_time_s=float(wall_time_s),
            n_samples=problem.n_samples,
            extra=dict(extra or {}),
            **assessment,
        )

    @property
    def residual_rms_rad_s(self) -> float:
        """RMS residual over the log's samples and axes, rad/s."""
        return float(np.sqrt(self.cost))

    def value(self, name: str) -> float:
        """One unknown by name (``fuel_consumed_kg``, ...)."""
        return float(self.theta[self.names.index(name)])

    def to_dict(self) -> dict[str, Any]:
        """The estimate file's content (JSON-ready)."""
        out: dict[str, Any] = {}
        for key, value in self.physical.items():
            out[key] = value
            out[f"{key}_std"] = self.physical_std.get(key)
        out.update(
            parameters={
                name: {"value": float(v), "std": float(s) if np.isfinite(s) else None, "identifiable": bool(ok)}
                for name, v, s, ok in zip(self.names, self.theta, self.theta_std, self.identifiable, strict=True)
            },
            parameterisation=self.parameterisation,
            insufficient_excitation=list(self.insufficient_excitation),
            estimator=self.estimator,
            options=self.options,
            seed=self.seed,
            cost_rad2_s2=self.cost,
            residual_rms_rad_s=self.residual_rms_rad_s,
            noise_std_rad_s=self.noise_std_rad_s,
            noise_source=self.noise_source,
            n_evaluations=self.n_evaluations,
            n_model_samples=self.n_model_samples,
            wall_time_s=self.wall_time_s,
            n_samples=self.n_samples,
            cost_history=self.cost_history,
            **self.extra,
        )
        return jsonable(out)

    def write_json(self, path: str | Path) -> Path:
        """Write :meth:`to_dict` to ``path`` atomically (a temporary file renamed into place), creating its folder."""
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        return write_json_atomic(path, self.to_dict())
