"""The leg thermal model: fixed segments plus one variable segment per leg.

A leg is a chain of segments along its axis. Every segment but one has a fixed
length (an aluminium body, say); exactly one has a variable length (the steel
screw), equal to the leg length minus the fixed lengths. A segment of length
``L`` and expansion coefficient ``cte`` at temperature ``T`` grows by
``cte * L * (T - T_ref)``.

With every segment of a leg at the same temperature change ``dT``, the leg grows
by ``dT * s(q)`` where the *sensitivity* is

    s(q) = sum_fixed(cte * L) + cte_var * (q - sum_fixed(L))      [mm/K]

This is what the paper's scaling uses: a growth ``dq_R`` measured at leg length
``q_R`` gives ``dT = dq_R / s(q_R)``, hence the growth at leg length ``q_S``:
``dq_S = dq_R * s(q_S) / s(q_R)``.

>>> import numpy as np
>>> model = LegThermalModel.uniform(
...     [("body", "aluminium", 23.1e-6, 148.0), ("screw", "steel", 11.5e-6, None)])
>>> s = model.sensitivity_mm_per_K(np.full(6, 248.0))
>>> float(np.round(s[0] * 1e6, 6))   # 23.1*148 + 11.5*100, in nm/K
4568.8
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from hexatherm.typing import FloatArray

#: (name, material, cte per K, length in mm or None for the variable segment)
SegmentSpec = tuple[str, str, float, float | None]


@dataclass(frozen=True)
class LegThermalModel:
    """Thermal expansion of the six legs, one segment table per leg.

    Segment tables of different lengths are padded with zero-length, zero-CTE
    segments, so every array has shape (6, S).

    Attributes
    ----------
    names : tuple of tuple of str
        Segment names per leg (unpadded).
    materials : tuple of tuple of str
        Segment materials per leg (unpadded).
    cte_per_K : ndarray, shape (6, S)
        Expansion coefficient of each segment.
    fixed_length_mm : ndarray, shape (6, S)
        Length of each fixed segment; 0 for the variable segment and padding.
    variable : ndarray of bool, shape (6, S)
        True at the one variable segment of each leg.
    reference_temperature_C : float
        Temperature at which the nominal geometry holds.
    """

    names: tuple[tuple[str, ...], ...]
    materials: tuple[tuple[str, ...], ...]
    cte_per_K: FloatArray
    fixed_length_mm: FloatArray
    variable: npt.NDArray[np.bool_]
    reference_temperature_C: float = 20.0

    @classmethod
    def from_segments(
        cls, per_leg: Sequence[Sequence[SegmentSpec]], reference_temperature_C: float = 20.0
    ) -> LegThermalModel:
        """Build the model from six segment lists ``(name, material, cte, length|None)``.

        Raises ValueError when a leg does not have exactly one variable segment, a
        fixed length is not positive or a CTE is not finite.
        """
        if len(per_leg) != 6:
            raise ValueError(f"need segment lists for 6 legs, got {len(per_leg)}")
        width = max(len(segments) for segments in per_leg)
        cte = np.zeros((6, width))
        length = np.zeros((6, width))
        variable = np.zeros((6, width), dtype=bool)
        for leg, segments in enumerate(per_leg):
            n_var = sum(1 for seg in segments if seg[3] is None)
            if n_var != 1:
                raise ValueError(
                    f"leg {leg + 1} must have exactly one variable segment, has {n_var}"
                )
            for j, (name, _material, seg_cte, seg_len) in enumerate(segments):
                if not np.isfinite(seg_cte):
                    raise ValueError(f"leg {leg + 1} segment {name!r}: cte is not finite")
                cte[leg, j] = seg_cte
                if seg_len is None:
                    variable[leg, j] = True
                elif not (np.isfinite(seg_len) and seg_len > 0):
                    raise ValueError(
                        f"leg {leg + 1} segment {name!r}: length must be positive, got {seg_len}"
                    )
                else:
                    length[leg, j] = seg_len
        return cls(
            names=tuple(tuple(seg[0] for seg in segs) for segs in per_leg),
            materials=tuple(tuple(seg[1] for seg in segs) for segs in per_leg),
            cte_per_K=cte,
            fixed_length_mm=length,
            variable=variable,
            reference_temperature_C=float(reference_temperature_C),
        )

    @classmethod
    def uniform(
        cls, segments: Sequence[SegmentSpec], reference_temperature_C: float = 20.0
    ) -> LegThermalModel:
        """The same segment list for all six legs."""
        return cls.from_segments([segments] * 6, reference_temperature_C)

    @property
    def total_fixed_length_mm(self) -> FloatArray:
        """Sum of the fixed segment lengths of each leg, shape (6,)."""
        return self.fixed_length_mm.sum(axis=1)

    @property
    def variable_cte_per_K(self) -> FloatArray:
        """CTE of the variable segment of each leg, shape (6,)."""
        return (self.cte_per_K * self.variable).sum(axis=1)

    def segment_lengths_mm(self, q_mm: npt.ArrayLike) -> FloatArray:
        """Lengths of all segments at leg lengths ``q`` (..., 6) -> (..., 6, S).

        The variable segment is ``q - sum(fixed lengths)``.
        """
        q = np.asarray(q_mm, dtype=float)
        var_len = q - self.total_fixed_length_mm
        return self.fixed_length_mm + self.variable * var_len[..., None]

    def sensitivity_mm_per_K(self, q_mm: npt.ArrayLike) -> FloatArray:
        """Growth per kelvin of each leg with all its segments equally heated, (..., 6):
        ``sum_s cte_s L_s``, affine in ``q`` (only the variable segment's length moves
        with it): ``sum_s cte_s fixed_s + cte_var (q - sum fixed)``, without the
        segments' (..., 6, S) lengths."""
        q = np.asarray(q_mm, dtype=float)
        fixed = (self.cte_per_K * self.fixed_length_mm).sum(axis=1)
        return fixed + self.variable_cte_per_K * (q - self.total_fixed_length_mm)

    def bound_sensitivity_mm_per_K(self, q_mm: npt.ArrayLike) -> FloatArray:
        """``sum_s |cte_s| L_s`` of each leg, (..., 6): the largest ``|growth|`` per kelvin
        when no segment's temperature changes by more than 1 K, either way (equal to
        :meth:`sensitivity_mm_per_K` when every CTE is positive)."""
        return (np.abs(self.cte_per_K) * self.segment_lengths_mm(q_mm)).sum(axis=-1)

    def growth_mm(
        self, q_mm: npt.ArrayLike, temperature_C: npt.ArrayLike, *, per_segment: bool = False
    ) -> FloatArray:
        """Thermal growth of each leg relative to the reference temperature.

        Parameters
        ----------
        q_mm : array_like, shape (..., 6)
            Leg lengths that set the variable segment's length (the commanded ones).
        temperature_C : array_like, shape (..., 6), or (..., 6, S) with ``per_segment``
            Temperature of each leg (all its segments alike) or of each segment.
        per_segment : bool
            Whether ``temperature_C`` gives one temperature per segment.

        Returns
        -------
        ndarray, shape (..., 6)
            ``sum_s cte_s * L_s * (T_s - T_ref)``.
        """
        temp = np.asarray(temperature_C, dtype=float)
        lengths = self.segment_lengths_mm(q_mm)
        if not per_segment:
            temp = temp[..., None]
        return (self.cte_per_K * lengths * (temp - self.reference_temperature_C)).sum(axis=-1)

    def scale_growth(
        self, growth_at_mm: npt.ArrayLike, q_at_mm: npt.ArrayLike, q_to_mm: npt.ArrayLike
    ) -> FloatArray:
        """The paper's scaling: growth measured at leg lengths ``q_at`` -> at ``q_to``.

        ``dT = dq_at / s(q_at)``, then ``dq_to = dT * s(q_to)``, leg by leg.
        """
        d_t = np.asarray(growth_at_mm, dtype=float) / self.sensitivity_mm_per_K(q_at_mm)
        return d_t * self.sensitivity_mm_per_K(q_to_mm)
