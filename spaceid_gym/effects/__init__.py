"""Hidden physical effects: what the truth holds that the nominal model leaves out, as physics.

* :mod:`.settings`: :class:`HiddenEffects`, the truth settings of the effects (the catalogue: each
  effect's fields, frames and units);
* :mod:`.draws`: their default sizes with the sources (:data:`DEFAULT_MAGNITUDES`, in
  :data:`MAGNITUDE_UNITS`) and random draws (:func:`draw_effect`);
* :mod:`.spec_strings`: the spec strings such as ``"slosh,delay[delay_s=0.03]"`` that ``spaceid simulate
  --hidden-effects`` and the env take (:func:`~spaceid_gym.effects.spec_strings.parse_hidden_effects`).

The names a user starts from are importable from this package too.
"""

from __future__ import annotations

from spaceid_gym.effects.draws import DEFAULT_MAGNITUDES as DEFAULT_MAGNITUDES
from spaceid_gym.effects.draws import MAGNITUDE_UNITS as MAGNITUDE_UNITS
from spaceid_gym.effects.draws import draw_effect as draw_effect
from spaceid_gym.effects.settings import EFFECT_NAMES as EFFECT_NAMES
from spaceid_gym.effects.settings import HiddenEffects as HiddenEffects
