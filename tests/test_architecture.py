"""The house rules of ARCHITECTURE.md: the flow runs one way (no module
imports a later stage), and no two modules import each other, however
indirectly (every import counts: at the top, inside a function, under
TYPE_CHECKING)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest
from wide import WIDE

PACKAGE = Path(__file__).resolve().parents[1] / "generator" / "gyrogen"
STAGES = (
    (
        "errors",
        "abi_rotors",
        "abi",
        "abi_groups",
        "limits",
        "methods",
        "tableaus",
        "physics",
        "setup_checks",
        "files",
    ),
    ("scene", "sweep_values"),
    ("symbolic",),
    ("codegen",),
    ("runtime",),
    ("oracle",),
    ("analysis",),
    ("commands", "api"),
    ("cli", "__main__"),
)
"""In the order the flow runs; a module may import its own stage and earlier ones."""


def stage(module: str) -> int:
    first = module.removeprefix("gyrogen.").split(".")[0]
    return next((i for i, names in enumerate(STAGES) if first in names), -1)


def modules() -> list[Path]:
    return sorted(p for p in PACKAGE.rglob("*.py") if "__pycache__" not in p.parts)


def name_of(path: Path) -> str:
    """gyrogen.a.b for a/b.py, gyrogen.a for a/__init__.py."""
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


NAMES = {name_of(p) for p in modules()}


def imports(path: Path) -> set[str]:
    """The package's modules that path imports anywhere in its text: `from
    gyrogen.a import b` is the module gyrogen.a.b when there is one, else
    gyrogen.a. A package enclosing path is left out (Python has started it
    before path runs), as the cycle tool of the style guide does."""
    me = name_of(path)
    base = me.split(".") if path.name == "__init__.py" else me.split(".")[:-1]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            up = base[: len(base) - node.level + 1] if node.level else []
            module = ".".join([*up, *([node.module] if node.module else [])])
            targets = [module, *(f"{module}.{a.name}" for a in node.names)]
        else:
            continue
        for target in targets:
            while target and target not in NAMES:
                target = target.rpartition(".")[0]
            if target and target != me and not me.startswith(target + "."):
                found.add(target)
    return found


def cycles() -> list[list[str]]:
    """Every set of two or more modules that reach one another by imports
    (the graph's strongly connected components), sorted."""
    graph = {name_of(p): imports(p) for p in modules()}

    def reach(start: str) -> set[str]:
        seen, todo = set(), [start]
        while todo:
            for m in graph[todo.pop()] - seen:
                seen.add(m)
                todo.append(m)
        return seen

    reached = {m: reach(m) for m in graph}
    found = {
        tuple(sorted(m2 for m2 in reached[m] if m in reached[m2])) for m in graph if m in reached[m]
    }
    return sorted(list(c) for c in found)


@pytest.mark.parametrize("path", modules(), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_no_module_imports_a_later_stage(path: Path) -> None:
    name = "gyrogen." + ".".join(path.relative_to(PACKAGE).with_suffix("").parts)
    later = [m for m in imports(path) if stage(m) > stage(name)]
    assert not later, f"{name} imports {later}"


def test_every_module_has_a_stage() -> None:
    assert all(stage("gyrogen." + p.relative_to(PACKAGE).parts[0].removesuffix(".py")) >= 0
               for p in modules() if p.name != "__init__.py" or p.parent != PACKAGE)  # fmt: skip


def test_no_import_cycle() -> None:
    """No module imports itself through others: a cycle leaves one of them
    half-initialized while the other runs, and ties modules that should
    stand apart."""
    found = cycles()
    assert not found, "import cycles:\n" + "\n".join(" <-> ".join(c) for c in found)


def test_running_compiled_code_never_imports_sympy() -> None:
    """runtime/, what a sweep worker imports and verify's comparison need no
    sympy (it cost every process 0.8 s of imports): a new interpreter
    imports them, and sympy is not among its modules."""
    import subprocess
    import sys

    code = (
        "import sys, gyrogen.runtime.build, gyrogen.runtime.compiled, gyrogen.runtime.rhs, "
        "gyrogen.runtime.segment, gyrogen.runtime.scene_build, "
        "gyrogen.analysis.sweep.engine, gyrogen.oracle.compare, gyrogen.commands.verify; "
        "print('sympy' in sys.modules)"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert proc.stdout.strip() == "False", proc.stderr


def test_the_rendering_digest_reads_every_module_rendering_imports() -> None:
    """The rendered sources are cached under a digest of the modules
    rendering can import (runtime/scene_build.py reads them from each file's
    import lines with a pattern): every module the syntax tree says those
    import, at any depth, is digested, each enclosing package too."""
    from gyrogen.runtime.scene_build import RENDERING, imported

    graph = {name_of(p): imports(p) for p in modules()}
    reached, todo = set(RENDERING), list(RENDERING)
    while todo:
        for m in graph[todo.pop()] - reached:
            reached.add(m)
            todo.append(m)
    for m in list(reached):
        while "." in m:
            m = m.rpartition(".")[0]
            reached.add(m)
    digested = {name_of(p) for p in imported(PACKAGE, RENDERING)}
    assert reached == digested, (reached - digested, digested - reached)


@pytest.mark.slow  # a scene rendered in a new interpreter: 10 s
@WIDE
def test_rendering_loads_no_module_its_digest_leaves_out() -> None:
    """A new interpreter renders a scene with events, outputs and
    sensitivities: every gyrogen module loaded by then is one the rendering
    digest reads (an edit elsewhere keeps the rendered sources cached)."""
    import subprocess
    import sys

    code = (
        "import sys\n"
        "from gyrogen.scene import parse, builtin_text\n"
        "from gyrogen.codegen.generate import render_all, unit_of\n"
        "from gyrogen.codegen.context import build_id\n"
        "scene = parse(builtin_text('torque_free') + '[[events]]\\nname = \"e\"\\n'\n"
        "              'expr = \"u1 - 0.1\"\\n[sensitivities]\\nwrt = [\"state\"]\\n', 'x')\n"
        "render_all(unit_of(scene)); build_id(scene)\n"
        "print(' '.join(sorted(m for m in sys.modules if m.startswith('gyrogen'))))\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr
    from gyrogen.runtime.scene_build import RENDERING, imported

    digested = {name_of(p) for p in imported(PACKAGE, RENDERING)}
    loaded = set(proc.stdout.split())
    assert "gyrogen.symbolic.variational" in loaded and "gyrogen.cli" not in loaded
    assert loaded <= digested, sorted(loaded - digested)


def test_the_adaptive_loops_share_the_driver() -> None:
    """The stop codes of the adaptive loops, their step counts, the last
    step's slack and the controllers' floors are written in
    codegen/integrators/driver.py alone; every other integrator module takes
    them from it."""
    words = ("ERR_MAX_STEPS", "ERR_STEP_UNDERFLOW", "ERR_SINGULAR", "stats.accepted",
             "stats.rejected", "LAST_STEP_SLACK", "PAIR_ERR_FLOOR", "err_floor")  # fmt: skip
    folder = PACKAGE / "codegen" / "integrators"
    assert "ERR_MAX_STEPS" in (folder / "driver.py").read_text(encoding="utf-8")
    for path in sorted(folder.glob("*.py")):
        if path.name == "driver.py":
            continue
        text = path.read_text(encoding="utf-8")
        for word in words:
            assert word not in text, f"{path.name} writes {word} (the driver's)"


def test_each_integrator_is_written_once() -> None:
    """Every integrator, and what they share (start-up, step
    control, linear algebra, sin and cos), is described once in
    codegen/integrators and printed to scalar C, SIMD lanes and Fortran. A
    template may call a printed function; none defines one or holds the
    step control's values."""
    import sympy as sm

    from gyrogen import methods
    from gyrogen.codegen.integrators import intrinsics, trig
    from gyrogen.codegen.integrators.program import program
    from gyrogen.symbolic.blocks import diagonal_blocks
    from gyrogen.symbolic.jet import decompose
    from gyrogen.symbolic.optimize import Block

    every = list(methods.METHODS.values())
    blocks = diagonal_blocks([sm.Integer(1)] * 49, 7)
    xs = sm.symbols("x0:2")
    jet = decompose(Block((), (sm.sin(xs[1]) / xs[0], xs[0] * xs[1])), xs)
    names = {"project_quaternion", "pair_integrate", "err_power", "complex_inverse"}
    for quaternion in (False, True):
        asked = [m.name for m in every]  # the lanes generated only when asked for too
        p = program(every, quaternion, True, blocks, jet, kinds=("angle",) * 7, asked=asked)
        for f in (*p.shared, *p.methods, *p.lanes, *p.handover):
            names.add(f.name)
    names |= {f.name.removeprefix("p_") for f in trig.functions("p", list(trig.VARIANTS))}
    names |= {f.name for f in intrinsics.functions()}
    control = ("err_old", "rejected_last", "h_new", "facmin", "facmax", "newton", "lu_end", "ksin")
    templates = sorted((PACKAGE / "templates").rglob("*.jinja"))
    assert templates
    for path in templates:
        text = path.read_text(encoding="utf-8")
        for name in names:
            defined = rf"(?m)^\s*(static|.*function|.*subroutine)\b[^\n(]*\b\w*{name}\s*\("
            assert not re.search(defined, text), f"{path.name} defines {name}"
        for word in control:
            assert word not in text, f"{path.name} holds the step control ({word})"


HAND_OFF = "hands a batch's trajectories to the printed integrators and back"
TEMPLATE_FUNCTIONS = {
    ("c/lanes.jinja", "pair_lanes"): HAND_OFF,
    ("c/lanes.jinja", "pair_batch"): HAND_OFF,
    ("cffi/glue.c.jinja", "gyrogen_rhs_batch"): HAND_OFF,
    ("cffi/glue.c.jinja", "gyrogen_batch"): HAND_OFF,
    ("cffi/glue.c.jinja", "gyrogen_each"): HAND_OFF,
    ("fmu/fmi2.c.jinja", "check_finite"): "the FMU's refusal of a value not finite",
    ("fmu/fmi2.c.jinja", "constants"): "the FMU's parameters into setup",
    ("fmu/fmi2.c.jinja", "outputs"): "the FMU's outputs from the printed output functions",
    ("fmu/fmi2.c.jinja", "set_parameters"): "the FMU's parameters into setup",
}
"""The functions on doubles the templates may define, and why; any other is
numerics, whose home is an IR function (codegen/integrators) printed to every
target. FMI 2.0's entry points (fmi2*) are the standard's interface. The
public integrators and their _batch loops are not written out: the macros
forward and batch (c/_macros.jinja, fortran/_macros.jinja) print their heads
from abi's signatures."""


def double_functions(templates: Path) -> set[tuple[str, str]]:
    """(template, name) of each function a template defines that takes or
    returns doubles: C definitions (a body follows) and Fortran procedures
    with real(c_double) arguments or result; a name's Jinja parts as words
    ({{ unit.prefix }}_{{ o.name }}: unit_prefix_o_name)."""

    def words(m: re.Match[str]) -> str:
        return re.sub(r"\W+", "_", m[1].strip())

    def strip(text: str) -> str:
        text = re.sub(r"\{#.*?#\}|\{%.*?%\}", "", text, flags=re.S)
        return re.sub(r"\{\{(.*?)\}\}", words, text, flags=re.S)

    params = r"[^;{}()]*(?:\([^()]*\)[^;{}()]*)*"  # one level of parentheses: double (*x)[N]
    c_def = re.compile(rf"(?m)^(?!\s)([\w ]*?[\w*]+)\s+\**\s*(\w+)\(({params})\)\s*\{{")
    f_def = re.compile(
        r"(?im)^[ \t]*([\w(), ]*?)\b(function|subroutine)\s+(\w+)\s*\(([^)]*)\)(.*?)\bend\s+\2\b",
        re.S,
    )
    found = set()
    for path in sorted(templates.rglob("*.jinja")):
        where = path.relative_to(templates).as_posix()
        text = strip(path.read_text(encoding="utf-8"))
        for m in c_def.finditer(text):
            ret, name, params = m.groups()
            if any(t in ret + params for t in ("double", "fmi2Real")):
                found.add((where, name))
        for m in f_def.finditer(text):
            prefix, _, name, _, body = m.groups()
            if "real(c_double)" in prefix or re.search(r"real\(c_double\)[^\n]*intent", body):
                found.add((where, name))
    return {f for f in found if not f[1].startswith("fmi2")}


def test_no_template_computes_on_doubles() -> None:
    """A template lays out a file: declarations, doc comments and the printed
    functions. One that defines a function on doubles holds numerics that the
    other target then writes again (the table lookup, fmax, floor were so)."""
    found = double_functions(PACKAGE / "templates")
    assert found, "the scan finds the functions it allows"
    extra = sorted(found - set(TEMPLATE_FUNCTIONS))
    assert not extra, f"templates define functions on doubles: {extra}"
    gone = sorted(set(TEMPLATE_FUNCTIONS) - found)
    assert not gone, f"allowed, yet no template defines them: {gone}"
