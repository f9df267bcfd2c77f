"""The block structure the generated LU relies on (gyrogen/lu_blocks.py)."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest
import sympy as sm
from wide import WIDE

from gyrogen import methods
from gyrogen.analysis.check.cases import quaternion_scene
from gyrogen.codegen.context import make_context
from gyrogen.codegen.generate import generate
from gyrogen.oracle import scene_view
from gyrogen.scene import Scene, builtin_names, builtin_text, load, parse
from gyrogen.symbolic.blocks import Blocks, diagonal_blocks


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
@WIDE
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


HARNESS = """
#include <stdio.h>
#include "{prefix}_ode.c"

#define N {macro}_NX

/* Reads A (its real part, then its imaginary part, row-major) and b (real,
   imaginary) from stdin; prints A_re^-1 b_re, then A^-1 b by real and
   imaginary part, by the generated decompositions and solves. */
int main(void)
{{
    double a[N * N], ar[N * N], ai[N * N], b[N], br[N], bi[N];
    int piv1[N], piv2[N], i;
    for (i = 0; i < N * N; ++i) if (scanf("%lf", &ar[i]) != 1) return 2;
    for (i = 0; i < N * N; ++i) if (scanf("%lf", &ai[i]) != 1) return 2;
    for (i = 0; i < N; ++i) if (scanf("%lf", &br[i]) != 1) return 2;
    for (i = 0; i < N; ++i) if (scanf("%lf", &bi[i]) != 1) return 2;
    for (i = 0; i < N * N; ++i) a[i] = ar[i];
    for (i = 0; i < N; ++i) b[i] = br[i];
    if (lu_decompose(a, piv1) || lu_decompose_complex(ar, ai, piv2)) return 3;
    lu_solve(a, piv1, b);
    lu_solve_complex(ar, ai, piv2, br, bi);
    for (i = 0; i < N; ++i) printf("%.17g\\n", b[i]);
    for (i = 0; i < N; ++i) printf("%.17g\\n", br[i]);
    for (i = 0; i < N; ++i) printf("%.17g\\n", bi[i]);
    return 0;
}}
"""


def block_matrix(blocks: Blocks, rng: np.random.Generator) -> np.ndarray:
    """A random matrix with the pattern the LU relies on: zero left of each
    row's block and beyond it outside U's pattern; the diagonal small, so
    that every block with a row below it pivots."""
    n = len(blocks.end)
    a = np.zeros((n, n))
    for r in range(n):
        s = blocks.start[r]
        for c in range(s, n):
            if c < blocks.end[r] or c in blocks.upper[s]:
                a[r, c] = rng.uniform(-1.0, 1.0)
        a[r, r] *= 1e-3
    return a


@pytest.mark.slow
@pytest.mark.parametrize("name", ["stiff_wheel", "rw4_hardware"])
@WIDE
def test_generated_lu_solves_block_systems(name: str, tmp_path: Path) -> None:
    """The checked-in scene's LU (decomposition unrolled over U's pattern,
    exchanges only where a block has a row below), real and complex, solves
    random systems of its Jacobian's pattern with rows exchanged, as numpy
    does."""
    scene = load(name)
    blocks = make_context(scene).lu_blocks
    assert blocks is not None
    src = Path(__file__).resolve().parent.parent / "generated" / name
    harness = tmp_path / "lu.c"
    harness.write_text(HARNESS.format(prefix=name, macro=name.upper()))
    exe = tmp_path / "lu"
    subprocess.run(["gcc", "-std=c99", "-O2", "-I", str(src), "-o", str(exe), str(harness),
                    str(src / f"{name}.c"), "-lm"], check=True)  # fmt: skip
    rng = np.random.default_rng(11)
    for _ in range(5):
        ar, ai = block_matrix(blocks, rng), block_matrix(blocks, rng)
        br, bi = rng.uniform(-1.0, 1.0, (2, len(ar)))
        given = " ".join(repr(float(v)) for v in (*ar.ravel(), *ai.ravel(), *br, *bi))
        out = subprocess.run([str(exe)], input=given, capture_output=True, text=True, check=True)
        got = np.array(out.stdout.split(), dtype=float).reshape(3, -1)
        np.testing.assert_allclose(got[0], np.linalg.solve(ar, br), rtol=1e-9, atol=1e-9)
        want = np.linalg.solve(ar + 1j * ai, br + 1j * bi)
        np.testing.assert_allclose(got[1] + 1j * got[2], want, rtol=1e-9, atol=1e-9)


def pattern_matrix(entries: list[sm.Expr], n: int, rng: np.random.Generator) -> np.ndarray:
    """A random matrix nonzero where J's entries can be (and on the diagonal,
    there small: every block with a row below it pivots)."""
    a = np.array([rng.uniform(-1.0, 1.0) if e != 0 else 0.0 for e in entries]).reshape(n, n)
    a[np.diag_indices(n)] = 1e-3 * rng.uniform(0.5, 1.0, n)
    return a


@pytest.mark.slow
@WIDE
def test_generated_lu_solves_an_augmented_system(tmp_path: Path) -> None:
    """The variational unit's LU (x, then Phi's entries, which read x: the
    coupling below x's rows) solves random systems of its Jacobian's pattern
    with rows exchanged in x's blocks and in Phi's, as numpy does; the
    complex matrices real in the coupling, as (a + i b) I - J is."""
    text = builtin_text("gyrostat") + '\n[sensitivities]\nwrt = ["state"]\n'
    unit = generate(parse(text, "gyrostat.toml"), tmp_path / "src").variational
    assert unit is not None and unit.optimized.jacobian is not None
    entries, n = list(unit.optimized.jacobian.outputs), unit.nx
    harness = tmp_path / "lu.c"
    harness.write_text(HARNESS.format(prefix=unit.prefix, macro=unit.prefix.upper()))
    exe = tmp_path / "lu"
    src = tmp_path / "src"
    subprocess.run(["gcc", "-std=c99", "-O2", "-I", str(src), "-o", str(exe), str(harness),
                    str(src / f"{unit.prefix}.c"), "-lm"], check=True)  # fmt: skip
    blocks = unit.lu_blocks
    assert blocks is not None and blocks.coupled
    coupled = np.zeros((n, n), dtype=bool)
    for r, cols in enumerate(blocks.coupled):
        coupled[r, list(cols)] = True
    rng = np.random.default_rng(12)
    for _ in range(5):
        ar, ai = pattern_matrix(entries, n, rng), pattern_matrix(entries, n, rng)
        ai[coupled] = 0.0
        br, bi = rng.uniform(-1.0, 1.0, (2, n))
        given = " ".join(repr(float(v)) for v in (*ar.ravel(), *ai.ravel(), *br, *bi))
        out = subprocess.run([str(exe)], input=given, capture_output=True, text=True, check=True)
        got = np.array(out.stdout.split(), dtype=float).reshape(3, -1)
        np.testing.assert_allclose(got[0], np.linalg.solve(ar, br), rtol=1e-9, atol=1e-9)
        want = np.linalg.solve(ar + 1j * ai, br + 1j * bi)
        np.testing.assert_allclose(got[1] + 1j * got[2], want, rtol=1e-9, atol=1e-9)


SHIFTED = """
#include <stdio.h>
#include "{prefix}_ode.c"

#define N {macro}_NX

/* Reads J (row-major), d, dr, di and b (real, imaginary) from stdin; with
   every entry of the iteration matrices set to a marker first (-(1 + k)),
   prints (d I - J)^-1 b_re, ((dr + i di) I - J)^-1 b by real and imaginary
   part, then the matrices' entries after lu_shift, lu_decompose and their
   complex twins. */
int main(void)
{{
    double J[N * N], a[N * N], ar[N * N], ai[N * N], b[N], br[N], bi[N], d, dr, di;
    int piv1[N], piv2[N], i;
    for (i = 0; i < N * N; ++i) if (scanf("%lf", &J[i]) != 1) return 2;
    if (scanf("%lf %lf %lf", &d, &dr, &di) != 3) return 2;
    for (i = 0; i < N; ++i) if (scanf("%lf", &br[i]) != 1) return 2;
    for (i = 0; i < N; ++i) if (scanf("%lf", &bi[i]) != 1) return 2;
    for (i = 0; i < N * N; ++i) a[i] = ar[i] = ai[i] = -(1.0 + i);
    for (i = 0; i < N; ++i) b[i] = br[i];
    lu_shift(J, d, a);
    lu_shift_complex(J, dr, di, ar, ai);
    if (lu_decompose(a, piv1) || lu_decompose_complex(ar, ai, piv2)) return 3;
    lu_solve(a, piv1, b);
    lu_solve_complex(ar, ai, piv2, br, bi);
    for (i = 0; i < N; ++i) printf("%.17g\\n", b[i]);
    for (i = 0; i < N; ++i) printf("%.17g\\n", br[i]);
    for (i = 0; i < N; ++i) printf("%.17g\\n", bi[i]);
    for (i = 0; i < N * N; ++i) printf("%.17g %.17g %.17g\\n", a[i], ar[i], ai[i]);
    return 0;
}}
"""


def shifted_solves(prefix: str, src: Path, entries: list[sm.Expr], blocks: Blocks,
                   tmp_path: Path) -> None:  # fmt: skip
    """lu_shift and lu_decompose (real and complex) of random J of the
    pattern, d I - J nearly singular on the diagonal (rows exchanged), solve
    as numpy does, and leave every entry outside Blocks.stored as it was."""
    n = len(blocks.end)
    harness, exe = tmp_path / "shifted.c", tmp_path / "shifted"
    harness.write_text(SHIFTED.format(prefix=prefix, macro=prefix.upper()))
    subprocess.run(["gcc", "-std=c99", "-O2", "-I", str(src), "-o", str(exe), str(harness),
                    str(src / f"{prefix}.c"), "-lm"], check=True)  # fmt: skip
    stored = np.zeros((n, n), dtype=bool)
    for r, cols in enumerate(blocks.stored):
        stored[r, cols] = True
    marker = -(1.0 + np.arange(n * n)).reshape(n, n)
    rng = np.random.default_rng(13)
    for _ in range(3):
        jac = pattern_matrix(entries, n, rng)
        d, dr, di = 2.0, 1.5, 0.7
        jac[np.diag_indices(n)] += np.array([d, dr])[rng.integers(0, 2, n)]
        br, bi = rng.uniform(-1.0, 1.0, (2, n))
        given = " ".join(repr(float(v)) for v in (*jac.ravel(), d, dr, di, *br, *bi))
        out = subprocess.run([str(exe)], input=given, capture_output=True, text=True, check=True)
        values = np.array(out.stdout.split(), dtype=float)
        got, mats = values[: 3 * n].reshape(3, -1), values[3 * n :].reshape(n, n, 3)
        eye = np.eye(n)
        np.testing.assert_allclose(got[0], np.linalg.solve(d * eye - jac, br), rtol=1e-9,
                                   atol=1e-9)  # fmt: skip
        want = np.linalg.solve((dr + 1j * di) * eye - jac, br + 1j * bi)
        np.testing.assert_allclose(got[1] + 1j * got[2], want, rtol=1e-9, atol=1e-9)
        for k in range(3):
            assert np.array_equal(mats[:, :, k][~stored], marker[~stored]), k


@pytest.mark.slow
@WIDE
def test_generated_lu_shift_touches_only_stored_entries(tmp_path: Path) -> None:
    """The checked-in stiff_wheel's iteration matrices and the variational
    unit's (x, then Phi's entries coupled to it) are built and factored
    where Blocks.stored says, the rest of the arrays never read or written."""
    scene = load("stiff_wheel")
    blocks, jac = make_context(scene).lu_blocks, make_context(scene).optimized.jacobian
    assert blocks is not None and jac is not None
    src = Path(__file__).resolve().parent.parent / "generated" / "stiff_wheel"
    shifted_solves("stiff_wheel", src, list(jac.outputs), blocks, tmp_path)
    text = builtin_text("gyrostat") + '\n[sensitivities]\nwrt = ["state"]\n'
    unit = generate(parse(text, "gyrostat.toml"), tmp_path / "src").variational
    assert unit is not None and unit.optimized.jacobian is not None and unit.lu_blocks
    shifted_solves(unit.prefix, tmp_path / "src", list(unit.optimized.jacobian.outputs),
                   unit.lu_blocks, tmp_path)  # fmt: skip


LANES = """
#include <math.h>
#include <stdio.h>
#include <string.h>

#define P_NX {n}
#define P_NX2 ({n} * {n})
#define P_LANES {lanes}
#define P_SIMD
#define P_RESTRICT

struct lanes {{
    double e2r[P_NX2][P_LANES], e2i[P_NX2][P_LANES], z2[P_NX][P_LANES], z3[P_NX][P_LANES];
    int piv2[P_NX][P_LANES], zero_pivot[P_LANES];
}};

{functions}

/* Reads each lane's ar, ai (row-major), br and bi from stdin; factors and
   solves each lane's system by the scalar functions and all lanes' by the
   functions over lanes; prints, a lane a line, whether the scalar
   decomposition found a zero pivot, whether the lanes' did, and whether
   the factors, pivots and solution are the same bits. */
int main(void)
{{
    static struct lanes L;
    double ar[P_NX2], ai[P_NX2], br[P_NX], bi[P_NX];
    int piv[P_NX], zero[P_LANES], i, l, same;
    for (l = 0; l < P_LANES; ++l) {{
        for (i = 0; i < P_NX2; ++i) if (scanf("%lf", &L.e2r[i][l]) != 1) return 2;
        for (i = 0; i < P_NX2; ++i) if (scanf("%lf", &L.e2i[i][l]) != 1) return 2;
        for (i = 0; i < P_NX; ++i) if (scanf("%lf", &L.z2[i][l]) != 1) return 2;
        for (i = 0; i < P_NX; ++i) if (scanf("%lf", &L.z3[i][l]) != 1) return 2;
        L.zero_pivot[l] = l % 2;  /* or-ed into: E1's, set for odd lanes */
    }}
    for (l = 0; l < P_LANES; ++l) zero[l] = L.zero_pivot[l];
    lu_decompose_complex_lanes(&L);
    lu_solve_complex_lanes(&L);
    rewind(stdin);  /* the inputs again, for the scalar functions */
    for (l = 0; l < P_LANES; ++l) {{
        int singular;
        for (i = 0; i < P_NX2; ++i) if (scanf("%lf", &ar[i]) != 1) return 2;
        for (i = 0; i < P_NX2; ++i) if (scanf("%lf", &ai[i]) != 1) return 2;
        for (i = 0; i < P_NX; ++i) if (scanf("%lf", &br[i]) != 1) return 2;
        for (i = 0; i < P_NX; ++i) if (scanf("%lf", &bi[i]) != 1) return 2;
        singular = lu_decompose_complex(ar, ai, piv);
        if (!singular) lu_solve_complex(ar, ai, piv, br, bi);
        same = 1;
        for (i = 0; i < P_NX2 && !singular; ++i)
            same &= !memcmp(&ar[i], &L.e2r[i][l], 8) && !memcmp(&ai[i], &L.e2i[i][l], 8);
        for (i = 0; i < P_NX && !singular; ++i)
            same &= piv[i] == L.piv2[i][l] && !memcmp(&br[i], &L.z2[i][l], 8)
                    && !memcmp(&bi[i], &L.z3[i][l], 8);
        printf("%d %d %d\\n", singular || zero[l], L.zero_pivot[l] != 0, same);
    }}
    return 0;
}}
"""


@pytest.mark.slow
@pytest.mark.parametrize("name", ["stiff_wheel", "cmg4_pyramid"])
@WIDE
def test_complex_lu_over_lanes_is_the_scalar_one_bit_for_bit(name: str, tmp_path: Path) -> None:
    """lu_decompose_complex_lanes and lu_solve_complex_lanes (radau5's E2
    over lanes, pivots and Smith's division by selection) give each lane the
    scalar functions' factors, pivots and solution bit for bit, rows
    exchanged and both cases of the division among the lanes; a lane with a
    zero pivot has zero_pivot set, and one set before (E1's) stays set."""
    from gyrogen.codegen.integrators import linear
    from gyrogen.codegen.ir.c import CPrinter
    from gyrogen.codegen.ir.lanes import LanesPrinter

    blocks = make_context(load(name)).lu_blocks
    assert blocks is not None
    n, lanes = len(blocks.end), 8
    state = {d.name: d for d in (*linear.lanes_state(), *linear.lanes_state_complex())}
    over = LanesPrinter("p", "P", {}, state)
    scalar = CPrinter("p", "P", {})
    functions = "\n".join([
        scalar.function(linear.decompose_complex(blocks, n)),
        scalar.function(linear.solve_complex(blocks, n)),
        over.function(linear.decompose_complex_lanes(blocks, n)),
        over.function(linear.solve_complex_lanes(blocks, n)),
    ])  # fmt: skip
    harness, exe = tmp_path / "lanes.c", tmp_path / "lanes"
    harness.write_text(LANES.format(n=n, lanes=lanes, functions=functions))
    subprocess.run(["gcc", "-std=c99", "-O2", "-o", str(exe), str(harness), "-lm"], check=True)
    rng = np.random.default_rng(14)
    given = tmp_path / "given.txt"
    values = []
    for lane in range(lanes):
        ar, ai = block_matrix(blocks, rng), block_matrix(blocks, rng)
        if lane in (2, 5):  # |im| > |re| on the diagonal: Smith's other case
            ai[np.diag_indices(n)] = 10.0 * rng.uniform(0.5, 1.0, n)
        if lane == 6:  # a zero column in the last block: singular
            ar[:, blocks.spans[-1][0]] = ai[:, blocks.spans[-1][0]] = 0.0
        br, bi = rng.uniform(-1.0, 1.0, (2, n))
        values += [*ar.ravel(), *ai.ravel(), *br, *bi]
    given.write_text(" ".join(repr(float(v)) for v in values))
    with given.open() as f:
        out = subprocess.run([str(exe)], stdin=f, capture_output=True, text=True, check=True)
    rows = [tuple(map(int, line.split())) for line in out.stdout.splitlines()]
    assert len(rows) == lanes
    for lane, (zero, zero_lanes, same) in enumerate(rows):
        assert zero == zero_lanes, lane
        assert zero == (lane == 6 or lane % 2 == 1), lane
        assert same, lane
