"""The satellite's mission: where its tank is and how fuel is consumed between windows.

A satellite has one fuel tank at a fixed position (unknown to estimators). Between two
identification windows (episodes) the satellite manoeuvres and burns fuel, so the fuel consumed
grows from episode to episode, by a random amount, until the usable fuel is spent.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.physics.inertia import RigidBodyInertia


@dataclass(frozen=True)
class FuelSchedule:
    """Fuel consumed per episode, as fractions of the full-tank base mass.

    Episode 0 has ``initial_fraction`` consumed; each later episode adds
    ``|N(mean_step_fraction, std_step_fraction)|``, capped at ``usable_fraction`` (empty tank).
    The defaults (usable fuel 25 % of the wet base mass, about 2 % burnt between windows) are
    typical of a geostationary servicing satellite: a 550 kg base carries about 140 kg of fuel.

    Attributes:
        initial_fraction: fuel consumed in the first episode / base mass.
        mean_step_fraction, std_step_fraction: fuel burnt between episodes / base mass.
        usable_fraction: usable fuel / base mass.
        tank_box_fraction: the tank position is drawn uniformly in a box of half-width
            ``tank_box_fraction * radius of gyration`` about the full-tank CoM, per axis.
    """

    initial_fraction: float = 0.05
    mean_step_fraction: float = 0.02
    std_step_fraction: float = 0.01
    usable_fraction: float = 0.25
    tank_box_fraction: float = 0.4

    def __post_init__(self) -> None:
        if not 0.0 <= self.initial_fraction <= self.usable_fraction < 1.0:
            raise SpaceIdInputError(
                "fuel schedule: expected 0 <= initial_fraction <= usable_fraction < 1, got "
                f"{self.initial_fraction!r} and {self.usable_fraction!r}"
            )
        if self.mean_step_fraction < 0.0 or self.std_step_fraction < 0.0 or self.tank_box_fraction < 0.0:
            raise SpaceIdInputError("fuel schedule: step mean/std and tank box fraction must be >= 0")

    def first(self, base_full: RigidBodyInertia) -> float:
        """Fuel consumed (kg) in the first episode."""
        return self.initial_fraction * base_full.mass_kg

    def next(self, consumed_kg: float, base_full: RigidBodyInertia, rng: np.random.Generator) -> float:
        """Fuel consumed (kg) in the episode after one with ``consumed_kg``."""
        step = abs(rng.normal(self.mean_step_fraction, self.std_step_fraction)) * base_full.mass_kg
        return min(consumed_kg + step, self.usable_fraction * base_full.mass_kg)

    def tank_half_width_m(self, base_full: RigidBodyInertia) -> float:
        """Half-width (m) of the box the tank position is drawn from."""
        radius_of_gyration = np.sqrt(np.trace(base_full.inertia_com_kgm2) / (2.0 * base_full.mass_kg))
        return float(self.tank_box_fraction * radius_of_gyration)

    def draw_tank_position(self, base_full: RigidBodyInertia, rng: np.random.Generator) -> FloatArray:
        """A tank position ``bf`` (m, base frame, relative to the full-tank CoM), shape (3,)."""
        half = self.tank_half_width_m(base_full)
        return rng.uniform(-half, half, size=3)
