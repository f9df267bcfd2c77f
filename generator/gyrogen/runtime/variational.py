"""The augmented system's layout on the Python side: y = (x, the entries of
Phi that can be nonzero), read from the manifest's "variational" section
(gyrogen.symbolic.variational), packed at the start and unpacked at the end."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class Layout:
    """Where Phi's entries sit in y, and their values at t0."""

    nx: int
    columns: tuple[str, ...]
    rows: np.ndarray
    cols: np.ndarray
    start: np.ndarray
    """Phi(t0)'s entries: 1 on the diagonal of the state's columns (Phi(t0)
    = I), 0 elsewhere (S(t0) = 0)."""

    @classmethod
    def of(cls, var: dict[str, Any]) -> Layout:
        entries = np.asarray(var["entries"], dtype=np.intp).reshape(-1, 2)
        rows, cols = entries[:, 0], entries[:, 1]
        start = ((rows == cols) & (cols < int(var["state_columns"]))).astype(np.float64)
        return cls(int(var["nx_state"]), tuple(var["columns"]), rows, cols, start)

    @property
    def ny(self) -> int:
        return self.nx + len(self.rows)

    def pack(self, x0: np.ndarray) -> np.ndarray:
        """y at t0 for one state (shape (nx,)) or a batch (shape (n, nx))."""
        y = np.empty((*x0.shape[:-1], self.ny))
        y[..., : self.nx] = x0
        y[..., self.nx :] = self.start
        return y

    def unpack(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """x and Phi (nx rows, one column per entry of columns) from y."""
        phi = np.zeros((*y.shape[:-1], self.nx, len(self.columns)))
        phi[..., self.rows, self.cols] = y[..., self.nx :]
        return y[..., : self.nx].copy(), phi
