"""Array type aliases shared by every layer.

The one place where hexatherm names its array types, so that a signature reads the
same in ``core``, ``io`` and the workflows.

>>> import numpy as np
>>> from hexatherm.typing import FloatArray
>>> x: FloatArray = np.zeros(3)
>>> x.dtype
dtype('float64')
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
"""An array of 64-bit floats (lengths in mm, angles in deg or rad as the name says)."""

IntArray = npt.NDArray[np.int64]
"""An array of 64-bit integers (indices, counts)."""

BoolArray = npt.NDArray[np.bool_]
"""An array of booleans (masks)."""
