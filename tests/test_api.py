"""The Python API's own argument checks: what the command line's option
types check, api.simulate checks too, in one line (SceneError, a ValueError)."""

from __future__ import annotations

import math

import pytest

from gyrogen import api
from gyrogen.errors import SceneError


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"t_end": 0.0}, "t_end = 0.0: must be a finite number of seconds above 0"),
        ({"t_end": -1.0}, "t_end = -1.0: must be"),
        ({"t_end": math.nan}, "t_end = nan: must be"),
        ({"t_end": math.inf}, "t_end = inf: must be"),
        ({"dt": 0.0}, "dt = 0.0: must be"),
        ({"dt": -0.1}, "dt = -0.1: must be"),
        ({"t_end": 1.0, "dt": 2.0}, "output step 2 s is longer than the span 1 s"),
        ({"t_end": 1e300, "dt": 1e-300}, "more than the limit"),
        ({"method": "bogus"}, "method 'bogus': not one of auto, "),
    ],
)
def test_simulate_refuses_bad_arguments_in_one_line(kwargs: dict, message: str) -> None:
    with pytest.raises(SceneError) as info:
        api.simulate("torque_free", **kwargs)
    assert message in str(info.value) and "\n" not in str(info.value)


def test_simulate_takes_the_span_it_is_given(tmp_path) -> None:
    """A span given is the span run (t_end=0.0 once meant the scene's own)."""
    df = api.simulate("torque_free", t_end=0.5, dt=0.25, out=tmp_path)
    assert list(df["t"]) == [0.0, 0.25, 0.5]
