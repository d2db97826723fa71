"""A tqdm progress bar over a stable-baselines3 training (stable-baselines3's own needs ``rich``)."""

from __future__ import annotations

from typing import Any

from stable_baselines3.common.callbacks import BaseCallback
from tqdm import tqdm


class ProgressBar(BaseCallback):
    """A tqdm progress bar over the training's ``total`` timesteps."""

    def __init__(self, total: int) -> None:
        super().__init__()
        self._total = total
        self._bar: Any = None

    def _on_training_start(self) -> None:
        self._bar = tqdm(total=self._total, unit="step", desc="training", mininterval=2.0)

    def _on_step(self) -> bool:
        self._bar.update(self.training_env.num_envs)
        return True

    def _on_training_end(self) -> None:
        self._bar.close()
