"""The mark of the cases past the suite's slice (`@WIDE`, or `marks=WIDE` on
one case of a parametrized test): a further scene, build or page on a path
the suite takes, or a test that cost 20 s or more of a worker in a full run
(ARCHITECTURE.md names the three the suite keeps whatever they cost). The
suite deselects them (conftest.py); `make test-wide` (GYROGEN_WIDE=1,
`-m wide`) runs them."""

from __future__ import annotations

import pytest

WIDE = pytest.mark.wide
