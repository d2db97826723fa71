"""Setting strings ``name[key=value,...]``: the one reader of the estimator, hidden-effect and effect-model specs.

A list of settings is written ``"a,b[key=value,other=[1,2]],c"``: items separated by the commas outside brackets,
each a name with optional options in brackets; an option's value may hold brackets and commas of its own
(``inertia=[0.9,0.4]``). This module reads the syntax only; what a name or a value means (and the message for a bad
one) is the caller's: :func:`estimators.evaluation.estimator_from_spec`, :func:`spaceid_gym.effects.spec_strings.parse_effect_spec`
and :func:`estimators.models.effect_models.parse_effects`.
"""

from __future__ import annotations

import re

from spaceid_gym.errors import SpaceIdInputError

#: a setting: a name of letters, digits, ``_``, ``.`` and ``-``, then optionally ``[...]`` (its options)
_SETTING = re.compile(r"\s*([\w.-]+)\s*(?:\[(.*)\])?\s*", re.DOTALL)


def split_outside_brackets(text: str, what: str) -> list[str]:
    """``text`` split at the commas not inside ``[...]`` (any depth), each part stripped, empty parts dropped.

    Unbalanced brackets raise :class:`SpaceIdInputError` naming ``what`` (the list or spec being read).
    """
    parts: list[str] = []
    depth, start = 0, 0
    for i, char in enumerate(text):
        depth += {"[": 1, "]": -1}.get(char, 0)
        if depth < 0:
            raise SpaceIdInputError(f"{what}: unbalanced ']' at character {i + 1} of {text!r}")
        if char == "," and depth == 0:
            parts.append(text[start:i])
            start = i + 1
    if depth:
        raise SpaceIdInputError(f"{what}: unclosed '[' in {text!r}")
    parts.append(text[start:])
    return [p.strip() for p in parts if p.strip()]


def parse_setting(item: str, what: str) -> tuple[str, list[str] | None]:
    """``"name[a=1,b=[2,3]]"`` -> ``("name", ["a=1", "b=[2,3]"])``; ``"name"`` -> ``("name", None)``.

    The options are the bracket's content split by :func:`split_outside_brackets` (so ``"name[]"`` gives ``[]``).

    Raises:
        SpaceIdInputError: naming ``what`` when ``item`` is not ``name`` or ``name[...]``, or its brackets are
            unbalanced.
    """
    match = _SETTING.fullmatch(item)
    if match is None:
        raise SpaceIdInputError(f"{what}: cannot read {item.strip()!r}; expected name or name[key=value,...]")
    options = match.group(2)
    return match.group(1), None if options is None else split_outside_brackets(options, what)
