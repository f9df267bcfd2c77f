"""The mark of the cases past the suite's slice: each takes a path a kept
case already takes, on another scene or build. The suite skips them;
`make test-wide` (GYROGEN_WIDE=1) runs them."""

from __future__ import annotations

import os

import pytest

WIDE = pytest.mark.skipif(
    not os.environ.get("GYROGEN_WIDE"), reason="a further point of the same path: make test-wide"
)
