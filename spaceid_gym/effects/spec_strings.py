"""Spec strings of hidden effects: the text that names the effects to simulate and their settings.

A spec string (:func:`parse_hidden_effects`, used by the env and ``spaceid simulate
--hidden-effects``) is comma-separated effect names, each optionally followed by ``[key=value,...]``
with ``magnitude`` or the effect's field names; vector and matrix values separate their numbers with
``;`` (row-major for the 3x3 matrix), and ``slosh_model`` is a word, e.g.
``"slosh,delay[delay_s=0.03],gyro_bias[magnitude=1e-4]"``,
``"external_torque[external_torque_Nm=1e-4;0;0,external_torque_rate_Nm_s=0;0;0]"`` or
``"slosh[slosh_model=pendulum,slosh_length_m=0.3,slosh_axis=0;0;1,slosh_frequency_hz=0.067,magnitude=37]"``.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from spaceid_gym.arrays import FloatArray
from spaceid_gym.effects.draws import draw_effect
from spaceid_gym.effects.settings import EFFECT_FIELDS, EFFECT_NAMES, FIELD_SHAPES, SLOSH_MODELS, HiddenEffects
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.robots.robot import Robot
from spaceid_gym.specs import parse_setting, split_outside_brackets


def _parse_value(spec: str, name: str, key: str, text: str) -> float | str | FloatArray:
    if key == "slosh_model":
        if text not in SLOSH_MODELS:
            raise SpaceIdInputError(
                f"hidden effects '{spec}': {name}[{key}=...] expected one of {', '.join(SLOSH_MODELS)}, got {text!r}"
            )
        return text
    try:
        values = [float(x) for x in text.split(";")]
    except ValueError:
        raise SpaceIdInputError(
            f"hidden effects '{spec}': {name}[{key}=...] expected a number or numbers separated by ';', got {text!r}"
        ) from None
    if not FIELD_SHAPES.get(key, ()):
        if len(values) != 1:
            raise SpaceIdInputError(f"hidden effects '{spec}': {name}[{key}=...] expected one number, got {text!r}")
        return values[0]
    shape = FIELD_SHAPES[key]
    if len(values) != math.prod(shape):
        raise SpaceIdInputError(
            f"hidden effects '{spec}': {name}[{key}=...] expected {math.prod(shape)} numbers separated by ';', got {text!r}"
        )
    return np.array(values).reshape(shape)


def parse_effect_spec(spec: str) -> list[tuple[str, dict[str, Any]]]:
    """The syntax of a spec string: ``[(effect name, {key: value})]``, checked, nothing drawn.

    Raises:
        SpaceIdInputError: unknown effect names or keys (listing the valid ones), malformed values,
            an effect given twice.
    """
    if not isinstance(spec, str) or not spec.strip():
        raise SpaceIdInputError(f"hidden effects: expected a spec such as 'slosh,delay[delay_s=0.03]', got {spec!r}")
    out: list[tuple[str, dict[str, Any]]] = []
    for item in split_outside_brackets(spec, f"hidden effects '{spec}'"):
        name, options = parse_setting(item, f"hidden effects '{spec}'")
        if name not in EFFECT_NAMES:
            raise SpaceIdInputError(
                f"hidden effects '{spec}': unknown effect '{name}'; expected one of {', '.join(EFFECT_NAMES)}"
            )
        if any(name == seen for seen, _ in out):
            raise SpaceIdInputError(f"hidden effects '{spec}': effect '{name}' given twice")
        valid = ("magnitude", *EFFECT_FIELDS[name])
        settings: dict[str, Any] = {}
        for pair in options or []:
            key, sep, text = (part.strip() for part in pair.partition("="))
            if not sep or key not in valid:
                raise SpaceIdInputError(
                    f"hidden effects '{spec}': {name}[{pair.strip()}] is not key=value with a valid key; "
                    f"expected keys {', '.join(valid)}"
                )
            settings[key] = _parse_value(spec, name, key, text)
        out.append((name, settings))
    return out


def parse_hidden_effects(spec: str, rng: np.random.Generator, robot: Robot, fuel_consumed_kg: float) -> HiddenEffects:
    """Draw the effects a spec string names (see the module docstring); given field values replace the draw's.

    Example: ``"slosh,delay[delay_s=0.03],gyro_bias[magnitude=1e-4]"``.
    """
    effects = HiddenEffects()
    for name, settings in parse_effect_spec(spec):
        magnitude = settings.pop("magnitude", None)
        drawn = draw_effect(name, rng, robot, fuel_consumed_kg, magnitude)
        effects = effects.combine(dataclasses.replace(drawn, **settings) if settings else drawn)
    return effects
