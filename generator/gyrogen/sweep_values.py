"""The values a sweep file spreads its variables over: a grid axis (list,
linspace, logspace) and a Monte Carlo distribution (uniform, normal,
lognormal, truncated), each checked to stay inside double range."""

from __future__ import annotations

import math

from pydantic import BaseModel, ConfigDict, Field, StrictInt, field_validator, model_validator

from gyrogen.limits import MAX_SWEEP_AXIS
from gyrogen.scene import Number


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


MAX_VALUE = 1e300
"""The largest magnitude a grid value or a draw may reach: the map's cell
edges and the draws' arithmetic stay inside double range (1.8e308)."""
TAIL = 9.0
"""Standard deviations within which a normal or lognormal draw falls (the
draws' 64-bit uniforms reach about 9.4 at their extremes, beyond in 1e-19)."""


def _normal_cdf(x: float) -> float:
    return 0.5 * math.erfc(-x / math.sqrt(2.0))


class Distribution(_Strict):
    """One of uniform (low, high), normal (mean, sd), lognormal (mu, sigma of
    the log), optionally truncated to [lo, hi]."""

    uniform: tuple[Number, Number] | None = None
    normal: tuple[Number, Number] | None = None
    lognormal: tuple[Number, Number] | None = None
    truncate: tuple[Number, Number] | None = None

    @property
    def kind(self) -> str:
        return next(k for k in ("uniform", "normal", "lognormal") if getattr(self, k) is not None)

    @property
    def args(self) -> tuple[float, float]:
        value: tuple[float, float] = getattr(self, self.kind)
        return value

    def cdf(self, x: float) -> float:
        a, b = self.args
        if self.kind == "uniform":
            return min(max((x - a) / (b - a), 0.0), 1.0)
        if self.kind == "lognormal":
            return 0.0 if x <= 0 else _normal_cdf((math.log(x) - a) / b)
        return _normal_cdf((x - a) / b)

    @model_validator(mode="after")
    def _one(self) -> Distribution:
        given = [k for k in ("uniform", "normal", "lognormal") if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError("give exactly one of uniform, normal, lognormal")
        a, b = self.args
        if self.kind == "uniform" and not a < b:
            raise ValueError(f"uniform = [{a:g}, {b:g}]: low must be below high")
        if self.kind != "uniform" and not b > 0:
            raise ValueError(f"{self.kind} = [{a:g}, {b:g}]: the spread must be > 0")
        reach = self.spread_reach
        if not reach <= MAX_VALUE:
            raise ValueError(
                f"{self.kind} = [{a:g}, {b:g}]: draws would reach {reach:.3g}, beyond "
                f"{MAX_VALUE:g} (double range)"
            )
        if self.truncate is not None:
            lo, hi = self.truncate
            if not lo < hi:
                raise ValueError(f"truncate = [{lo:g}, {hi:g}]: lo must be below hi")
            if not self.cdf(hi) - self.cdf(lo) > 1e-12:
                raise ValueError(f"truncate = [{lo:g}, {hi:g}] leaves no probability")
        return self

    @property
    def spread_reach(self) -> float:
        """The largest |draw| (or |high - low|) the distribution reaches
        untruncated: TAIL spreads out for a normal or lognormal one."""
        a, b = self.args
        return {
            "uniform": max(abs(a), abs(b), abs(b - a)),
            "normal": abs(a) + TAIL * b,
            "lognormal": math.exp(min(a + TAIL * b, 709.0)) if a + TAIL * b < 709.0 else math.inf,
        }[self.kind]

    @property
    def reach(self) -> float:
        """The largest |draw|: spread_reach's, within the truncation."""
        a, b = self.args
        untruncated = max(abs(a), abs(b)) if self.kind == "uniform" else self.spread_reach
        if self.truncate is None:
            return untruncated
        return min(untruncated, max(map(abs, self.truncate)))


class Axis(_Strict):
    """The values of one grid axis."""

    values: list[Number] | None = Field(default=None, alias="list")
    linspace: tuple[Number, Number, StrictInt] | None = None
    logspace: tuple[Number, Number, StrictInt] | None = None
    """10**a to 10**b."""

    @model_validator(mode="after")
    def _one(self) -> Axis:
        given = [x for x in (self.values, self.linspace, self.logspace) if x is not None]
        if len(given) != 1:
            raise ValueError("give exactly one of list, linspace, logspace")
        n = len(self.values) if self.values is not None else self.spaced[2]
        if not 1 <= n <= MAX_SWEEP_AXIS:
            raise ValueError(f"{n} values: from 1 to {MAX_SWEEP_AXIS:,}")
        if self.logspace is not None and max(map(abs, self.logspace[:2])) > 300:
            raise ValueError("logspace exponents beyond +-300 leave double range")
        ends = self.values or (self.linspace[:2] if self.linspace is not None else ())
        if ends and not max(map(abs, ends)) <= MAX_VALUE:
            raise ValueError(f"values beyond +-{MAX_VALUE:g} leave double range on the map")
        return self

    @property
    def spaced(self) -> tuple[float, float, int]:
        value = self.linspace if self.linspace is not None else self.logspace
        assert value is not None
        return value

    @property
    def size(self) -> int:
        return len(self.values) if self.values is not None else self.spaced[2]

    @property
    def reach(self) -> float:
        """The largest |value| on the axis (one of its values)."""
        if self.values is not None:
            return max(map(abs, self.values))
        a, b, _ = self.spaced
        return max(abs(a), abs(b)) if self.linspace is not None else 10.0 ** max(a, b)


MAX_TILT_DEG = 90.0
"""The largest cone a misalignment's tilt may be bounded by (degrees): past
it the axis would turn back on itself."""


class Misalignment(_Strict):
    """A runtime axis tilted by a small rotation: about a direction
    perpendicular to it drawn uniformly, by an angle (degrees) drawn from
    angle and restricted to [-max_deg, max_deg] (the tilt is its size); the
    axis stays a unit vector."""

    angle: Distribution
    max_deg: Number
    """The cone's half angle (degrees): in (0, MAX_TILT_DEG]."""

    @field_validator("max_deg")
    @classmethod
    def _bounded(cls, v: float) -> float:
        if not 0.0 < v <= MAX_TILT_DEG:
            raise ValueError(f"must be in (0, {MAX_TILT_DEG:g}] degrees (got {v:g})")
        return v

    @model_validator(mode="after")
    def _reaches(self) -> Misalignment:
        lo, hi = self.bounds
        if not lo < hi or not self.angle.cdf(hi) - self.angle.cdf(lo) > 1e-12:
            raise ValueError(
                f"angle: leaves no probability within +-max_deg = {self.max_deg:g} degrees"
            )
        return self

    @property
    def bounds(self) -> tuple[float, float]:
        """[-max_deg, max_deg], within angle's own truncate if it has one."""
        lo, hi = self.angle.truncate or (-math.inf, math.inf)
        return max(lo, -self.max_deg), min(hi, self.max_deg)

    @property
    def cone(self) -> Distribution:
        """angle restricted to bounds (degrees)."""
        return self.angle.model_copy(update={"truncate": self.bounds})
