"""Sensitivities: the [sensitivities] table, the generated variational
system (Phi' = J_x Phi, S' = J_x S + J_p) and Compiled.integrate_var."""

from __future__ import annotations

import pytest

from gyrogen.errors import SceneError
from gyrogen.scene import builtin_text, parse


def scene_with(name: str, table: str):
    return parse(builtin_text(name) + "\n[sensitivities]\n" + table + "\n", f"{name}.toml")


def test_wrt_accepted():
    s = scene_with("gyrostat", 'wrt = ["state", "T"]')
    assert s.sensitivities is not None
    assert s.sensitivities.wrt == ["state", "T"]
    assert s.sensitivities.error == "all"


@pytest.mark.parametrize(
    ("name", "table", "message"),
    [
        ("gyrostat", 'wrt = ["state", "state"]', "sensitivities.wrt: 'state' is listed twice"),
        ("gyrostat", 'wrt = ["T", "g", "T"]', "sensitivities.wrt: 'T' is listed twice"),
        (
            "gyrostat",
            'wrt = ["state", "bogus"]',
            "sensitivities.wrt[1]: 'bogus' is neither \"state\" nor a runtime parameter",
        ),
        ("dual_spin", 'wrt = ["J"]', "sensitivities.wrt[0]: 'J' is folded to a number"),
        ("gyrostat", "wrt = []", "sensitivities.wrt: List should have at least 1 item"),
        ("gyrostat", 'wrt = ["T"]\nerror = "phi"', "sensitivities.error: Input should be"),
        ("gyrostat", 'wrt = ["T"]\nstep = 1', "sensitivities.step: unknown key"),
    ],
)
def test_wrt_refused_in_one_line(name, table, message):
    with pytest.raises(SceneError) as info:
        scene_with(name, table)
    text = str(info.value)
    assert message in text
    assert "\n" not in text


def test_build_id_unchanged_without_the_table():
    """A scene without [sensitivities] dumps as before (its build id)."""
    s = parse(builtin_text("gyrostat"), "g.toml")
    assert "sensitivities" not in s.model_dump(mode="json")
