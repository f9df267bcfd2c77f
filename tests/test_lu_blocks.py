"""The block structure the generated LU relies on (gyrogen/lu_blocks.py)."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sm

from gyrogen import methods
from gyrogen.analysis.check.cases import quaternion_scene
from gyrogen.codegen.context import make_context
from gyrogen.oracle import scene_view
from gyrogen.scene import Scene, builtin_names, load
from gyrogen.symbolic.blocks import diagonal_blocks


def pattern(rows: list[str]) -> list[sm.Expr]:
    """Row-major entries from strings of 'x' (nonzero) and '.' (zero)."""
    return [sm.Symbol("a") if ch == "x" else sm.S.Zero for row in rows for ch in row]


def test_diagonal_gives_one_block_a_state() -> None:
    b = diagonal_blocks(pattern(["x..", ".x.", "..x"]), 3)
    assert b.spans == ((0, 1), (1, 2), (2, 3))
    assert b.lower == [[], [], []]
    assert b.upper == ((), (), ())


def test_full_pattern_is_one_dense_block() -> None:
    b = diagonal_blocks(pattern(["xxx", "xxx", "xxx"]), 3)
    assert b.spans == ((0, 3),)
    assert b.lower == [[], [0], [0, 1]]
    assert b.upper == ((1, 2), (2,), ())


def test_an_entry_below_merges_the_rows_between() -> None:
    # J[3][1] couples rows 1..3; row 0 and row 4 stay alone.
    b = diagonal_blocks(pattern(["x...x", ".x...", "..x..", ".x.x.", "....x"]), 5)
    assert b.spans == ((0, 1), (1, 4), (4, 5))
    assert b.start == [0, 1, 1, 1, 4] and b.end == [1, 4, 4, 4, 5]
    # U's row 1 fills in across its block; nothing of the block reads column 4.
    assert b.upper[1] == (2, 3) and b.upper[0] == (4,)


def test_wrong_size_is_refused() -> None:
    with pytest.raises(ValueError, match="expected 9"):
        diagonal_blocks(pattern(["xx", "xx"]), 3)


def numeric_jacobian(scene: Scene) -> np.ndarray:
    """Central differences of the numpy witness at a random state: an entry
    is exactly 0 when f_i does not read x_j."""
    rng = np.random.default_rng(7)
    p = np.array([scene.simulate.parameters.get(n, 1.0) for n in scene.runtime])
    x = 0.5 + 0.3 * rng.standard_normal(len(scene.states))
    n = len(x)
    jac = np.empty((n, n))
    for j in range(n):
        e = np.zeros(n)
        e[j] = 1e-6
        jac[:, j] = (scene_view.rhs(scene, x + e, p)[0] - scene_view.rhs(scene, x - e, p)[0]) / 2e-6
    return jac


SCENES = [name for name in builtin_names() if methods.needs_jacobian(load(name).integrators)]


@pytest.mark.slow
@pytest.mark.parametrize("name", [*SCENES, "quaternion"])
def test_blocks_cover_the_witness_jacobian(name: str) -> None:
    """What the template leaves out of the LU is zero in the paper's model:
    no entry below the diagonal outside a block, and no entry of a block's
    rows beyond it outside U's pattern."""
    scene = quaternion_scene() if name == "quaternion" else load(name)
    blocks = make_context(scene).lu_blocks
    assert blocks is not None
    jac = numeric_jacobian(scene)
    for i in range(len(jac)):
        for j in range(len(jac)):
            if j < blocks.start[i] or (j >= blocks.end[i] and j not in blocks.upper[i]):
                assert jac[i, j] == 0.0, (scene.states[i], scene.states[j], jac[i, j])
    # the structure is worth having: the attitude and the speeds split
    assert len(blocks.spans) > 2
