"""The mark of the cases past the suite's slice (`@WIDE`, or `marks=WIDE` on
one case of a parametrized test): each takes a path a kept case or a cheaper
test already takes, on another scene, build or page, or at a size the suite
cannot afford in its ten minutes. The suite deselects them (conftest.py);
`make test-wide` (GYROGEN_WIDE=1, `-m wide`) runs them."""

from __future__ import annotations

import pytest

WIDE = pytest.mark.wide
