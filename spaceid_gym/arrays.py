"""Array type aliases shared by every layer (one definition instead of one per module)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

#: a float64 array of any shape; the docstring of each use gives its shape, frame and units
FloatArray = NDArray[np.float64]
