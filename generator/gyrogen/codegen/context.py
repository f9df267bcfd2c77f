"""Everything one scene's generated files need, language-neutral."""

from __future__ import annotations

import hashlib
import json
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import cached_property
from importlib.metadata import version

import sympy as sm

import gyrogen
from gyrogen.abi import Code, output_doc, setup_codes_of
from gyrogen.abi_groups import StateKind, state_kind
from gyrogen.abi_rotors import AXIS, GIMBAL_AXIS, GIMBAL_KEYS, POSITION, rotor_name
from gyrogen.codegen.integrators.driver import EV_SUBINTERVALS, Event, Grid
from gyrogen.codegen.integrators.program import Program, program
from gyrogen.codegen.integrators.taylor import UNMEASURED, state_scales
from gyrogen.methods import IMPLICIT, METHODS, Method, needs_jacobian
from gyrogen.scene import Outputs, Scene
from gyrogen.scene.rotors import Gimbal, Rotor
from gyrogen.setup_checks import CHECKS, Check, cluster_checks
from gyrogen.symbolic.blocks import Blocks, diagonal_blocks
from gyrogen.symbolic.equations import TIME, Equations
from gyrogen.symbolic.jet import Jet, decompose
from gyrogen.symbolic.optimize import Block, Optimized, optimize
from gyrogen.symbolic.specialize import specialize
from gyrogen.symbolic.variational import Variational


@dataclass(frozen=True)
class Row:
    index: int
    name: str
    unit: str
    doc: str


@dataclass(frozen=True)
class Local:
    """A parameter setup reads: from p[index] (runtime) or a folded value."""

    name: str
    index: int | None
    value: float | None


@dataclass(frozen=True)
class Table:
    """A tabulated torque: the function <prefix>_<name>(t) and its local."""

    name: str
    points: list[tuple[float, float]]
    doc: str


@dataclass(frozen=True)
class Output:
    name: str
    block: Block
    unit: str
    doc: str

    @property
    def size(self) -> int:
        return len(self.block.outputs)


@dataclass(frozen=True)
class SceneContext:
    scene: Scene
    equations: Equations
    optimized: Optimized

    @property
    def states(self) -> tuple[sm.Symbol, ...]:
        return self.equations.states

    @property
    def params(self) -> tuple[sm.Symbol, ...]:
        return self.equations.params

    @property
    def prefix(self) -> str:
        return self.scene.name

    @property
    def macro(self) -> str:
        return self.scene.name.upper()

    @property
    def nx(self) -> int:
        return len(self.states)

    @property
    def np(self) -> int:
        return len(self.params)

    @property
    def nc(self) -> int:
        return self.optimized.nc

    @cached_property
    def ops(self) -> dict[str, int]:
        ops = {"setup": self.optimized.setup.ops, "rhs": self.optimized.rhs.ops}
        if self.optimized.augmented is not None:
            ops["var_rhs"] = self.optimized.augmented.ops
        ops.update({o.name: o.block.ops for o in self.outputs})
        if self.events is not None:
            ops["events"] = self.events.block.ops
        if self.optimized.jacobian is not None:
            ops["jac"] = self.optimized.jacobian.ops
        if self.optimized.linear is not None:
            ops["linear"] = self.optimized.linear.ops
        return ops

    @property
    def inputs(self) -> tuple[str, ...]:
        """The linear model's inputs (outputs.linear_model), else none."""
        pert = self.equations.perturbed
        return pert.names if pert is not None else ()

    @property
    def ny(self) -> int:
        """The outputs' values, one after another: the linear model's y."""
        return sum(o.size for o in self.outputs)

    @property
    def linear_sizes(self) -> dict[str, tuple[int, int]]:
        """The linear model's matrices, (rows, columns) each."""
        nx, nu, ny = self.nx, len(self.inputs), self.ny
        return {"A": (nx, nx), "B": (nx, nu), "C": (ny, nx), "D": (ny, nu)}

    @cached_property
    def lu_blocks(self) -> Blocks | None:
        """The diagonal blocks the implicit method's LU works in."""
        jac = self.optimized.jacobian
        return None if jac is None else diagonal_blocks(jac.outputs, self.nx)

    @cached_property
    def jet(self) -> Jet | None:
        """The rhs as elementary operations, when a Taylor method expands it."""
        if not any(m.taylor for m in self.methods):
            return None
        scales = state_scales([s.name for s in self.states])
        return replace(decompose(self.optimized.rhs, self.states), scales=scales)

    @cached_property
    def variational(self) -> VariationalContext | None:
        """The augmented system (x, Phi, S) as a unit of its own under the
        prefix <prefix>_var, with the scene's setup (its constants include
        the variational system's): every explicit integrator instantiated
        for it, scalar, lanes and Fortran, through the same descriptions."""
        var = self.optimized.variational
        if var is None or self.optimized.augmented is None:
            return None
        jac = self.optimized.augmented_jacobian
        kept = [m for m in self.scene.integrators if jac is not None or m not in IMPLICIT]
        scene = self.scene.model_copy(
            update={
                "name": f"{self.scene.name}_var",
                "outputs": Outputs(),
                "integrators": kept,
                "lanes": [m for m in self.scene.lanes if m in kept],
                "sensitivities": None,
            }
        )
        eqs = replace(
            self.equations, states=(*self.states, *var.symbols), outputs={}, perturbed=None
        )
        opt = Optimized(setup=self.optimized.setup, rhs=self.optimized.augmented,
                        lumped=self.optimized.lumped, jacobian=jac)  # fmt: skip
        return VariationalContext(scene, eqs, opt, base=self)

    @property
    def measured(self) -> int | None:
        """How many leading states the integrators' error norms measure:
        every one (None), or an augmented system's x alone."""
        return None

    @property
    def methods(self) -> list[Method]:
        """The scene's integrators, from the registry (gyrogen.methods)."""
        return [METHODS[m] for m in self.scene.integrators]

    @property
    def laned(self) -> list[Method]:
        """The integrators whose C batches run over SIMD lanes (radau5's
        only where the scene's `lanes` asks for them)."""
        return [m for m in self.methods if m.laned(self.scene.lanes)]

    @property
    def outputs(self) -> list[Output]:
        doc = output_doc(self.cluster)
        return [Output(n, b, *doc[n]) for n, b in self.optimized.outputs.items()]

    @property
    def events(self) -> Output | None:
        """The scene's events g(t, x) as one function, <prefix>_events (out[k]:
        event k's g), beside the outputs; None without events."""
        b = self.optimized.events
        names = ", ".join(e.name for e in self.scene.events)
        return None if b is None else Output("events", b, "", f"the events' g(t, x): {names}")

    @cached_property
    def program(self) -> Program:
        """The integrators' functions, one description printed to every
        target (gyrogen.codegen.integrators.program)."""
        return program(
            self.methods,
            self.quaternion,
            self.uses_time,
            self.lu_blocks,
            self.jet,
            self.event_grid,
            self.measured,
            self.kinds,
            self.scene.table_times,
            self.scene.lanes,
        )

    @property
    def kinds(self) -> tuple[StateKind, ...]:
        """How each state enters an error scale (abi_groups.state_kind)."""
        return tuple(state_kind(s.name) for s in self.states)

    @property
    def event_grid(self) -> Grid | None:
        """The events as the integrators' _events twins take them, or None."""
        if not self.scene.events or self.events is None:
            return None
        timed = {TIME, *self.equations.inputs}  # the time, or a table of it
        moving = any(e.free_symbols & timed for e in self.equations.events)
        pieces = EV_SUBINTERVALS if moving else 1
        read = self.optimized.events.free_symbols if self.optimized.events else set()
        reads = tuple(i for i, s in enumerate(self.states) if s in read)
        return Grid(
            tuple(Event(e.sign, e.terminal) for e in self.scene.events),
            pieces,
            reads if len(reads) < len(self.states) else (),
        )

    @property
    def cluster(self) -> bool:
        """A reaction-wheel cluster (the scene's [[rotors]]), not the paper's one rotor."""
        return bool(self.scene.rotors)

    @property
    def checks(self) -> tuple[Check, ...]:
        """setup's checks: a cluster's folded inertial values are checked by
        the scene validator, so its setup makes 'finite', 'bound' and the
        checks of its runtime axial inertias (setup_checks.cluster_checks).
        With every value folded the constants are the scene validator's
        bounded numbers' and 'constants' is not made."""
        out = self._checks
        return out if self.np else tuple(c for c in out if c.kind != "constants")

    @property
    def _checks(self) -> tuple[Check, ...]:
        if not self.cluster:
            return CHECKS
        values: dict[str, float | str] = dict(self.scene.parameters)
        for k, r in enumerate(self.scene.rotors, 1):
            values.update({rotor_name(key, k): getattr(r, key) for key in ("m", "I", "J")})
            if r.gimbal is not None:
                values.update({rotor_name(key, k): v for key, v in r.gimbal.inertial().items()})
            values.update({rotor_name(key, k): r.axis for key in AXIS if r.axis == "runtime"})
            if r.gimbal is not None and r.axes_at_runtime:  # the pair's perpendicularity
                for keys, axis in ((AXIS, r.axis), (GIMBAL_AXIS, r.gimbal.axis)):
                    parts = ("runtime",) * 3 if axis == "runtime" else axis
                    values.update(zip((rotor_name(key, k) for key in keys), parts, strict=True))
        return cluster_checks(values, len(self.scene.rotors))

    @property
    def setup_codes(self) -> list[Code]:
        """The codes setup can return (those of its checks)."""
        made = {c.code for c in self.checks}
        return [c for c in setup_codes_of(self.cluster) if c.value == 0 or c.value in made]

    @property
    def rotor_doc(self) -> list[str]:
        """A cluster's rotors for the header: axis, position, law, friction, limit."""
        out = []
        for k, r in enumerate(self.scene.rotors, 1):
            at = _vector_doc(r.position, POSITION, k)
            if r.gimbal is None:
                g = _vector_doc(r.axis if r.axis == "runtime" else r.unit_axis, AXIS, k)
                g += " normalized" if r.axis == "runtime" else ""
                out.append(f"Rotor B{k}: axis g{k} = ({g}) in A, B{k}* at ({at}) m from A*;")
            else:
                out += _gimbal_axes_doc(r, k, at)
            out.append(f"  {_law_doc(r.law(), r.torque, k)};")
            limit = "" if r.tau_max is None else f", |T| clamped to {r.tau_max:g} N m"
            out.append(f"  friction b = {r.b:g} N m s{limit}{';' if r.gimbal else '.'}")
            if r.gimbal is not None:
                out += _gimbal_law_doc(r.gimbal, k)
        return out

    def outputs_size(self, function: str) -> int:
        """The size of an output function's out[], 0 for any other function."""
        every = [*self.outputs, *([self.events] if self.events else [])]
        return next((o.size for o in every if o.name == function), 0)

    @property
    def torque_table(self) -> list[tuple[float, float]] | None:
        return self.scene.effects.torque_table

    @property
    def torque_tables(self) -> list[Table]:
        """Every T(t) table: the scene's torque, or each cluster rotor's
        torque_k, then each gimbal's torqueg_k."""
        if self.torque_table:
            doc = "T(t), piecewise linear through the scene's table, constant outside it."
            return [Table("torque", self.torque_table, doc)]
        return [
            Table(
                f"torque_{k}",
                r.torque_table,
                f"T_{k}(t), rotor B{k}'s motor torque, piecewise linear through its table, "
                "constant outside it.",
            )
            for k, r in enumerate(self.scene.rotors, 1)
            if r.torque_table
        ] + [
            Table(
                f"torqueg_{k}",
                r.gimbal.torque_table,
                f"Tg_{k}(t), gimbal G{k}'s motor torque, piecewise linear through its table, "
                "constant outside it.",
            )
            for k, r in enumerate(self.scene.rotors, 1)
            if r.gimbal is not None and r.gimbal.torque_table
        ]

    @property
    def folded_summary(self) -> str:
        return ", ".join(f"{n} = {v!r}" for n, v in self.scene.folded().items())

    @property
    def quaternion(self) -> bool:
        """The attitude is Euler parameters, x[0..3]."""
        return self.scene.attitude == "quaternion"

    @property
    def uses_time(self) -> bool:
        return bool(self.equations.inputs)

    @property
    def state_rows(self) -> list[Row]:
        return [Row(i, s.name, *self.scene.unit_and_doc(s.name)) for i, s in enumerate(self.states)]

    @property
    def param_rows(self) -> list[Row]:
        return [Row(i, s.name, *self.scene.unit_and_doc(s.name)) for i, s in enumerate(self.params)]

    @cached_property
    def setup_locals(self) -> list[Local]:
        """The checked parameters, then the runtime ones the constants use."""
        runtime = {s.name: i for i, s in enumerate(self.params)}
        folded = self.scene.folded()
        used = self.optimized.setup.free_symbols
        names = list(self.equations.checks)
        names += [s.name for s in self.params if s in used and s.name not in names]
        return [Local(n, runtime.get(n), folded.get(n)) for n in names]

    @property
    def cond_index(self) -> int:
        """c[cond_index] holds the condition number of the coupled block."""
        return self.nc - 1

    @cached_property
    def build_id(self) -> str:
        return build_id(self.scene)

    @property
    def versions(self) -> dict[str, str]:
        return versions()

    @property
    def functions(self) -> dict[str, dict[str, str]]:
        """Exported names by language: C's, and Fortran's module and bind(C)
        names (its strerror functions return a character, so they are
        Fortran-only and not listed)."""
        p = self.prefix
        c = {"setup": f"{p}_setup", "rhs": f"{p}_rhs", "strerror": f"{p}_strerror"}
        f = {"module": f"{p}_mod", "setup": f"{p}_f_setup", "rhs": f"{p}_f_rhs"}
        for o in [*self.outputs, *([self.events] if self.events else [])]:
            c[o.name] = f"{p}_{o.name}"
            f[o.name] = f"{p}_f_{o.name}"
        if self.optimized.jacobian is not None:
            c["jac"], f["jac"] = f"{p}_jac", f"{p}_f_jac"
        if self.optimized.linear is not None and "c" in self.scene.targets:
            c["linear"] = f"{p}_linear"  # C only
        for m in self.scene.integrators:
            c[m], f[m] = f"{p}_{m}", f"{p}_f_{m}"
            c[f"{m}_batch"], f[f"{m}_batch"] = f"{p}_{m}_batch", f"{p}_f_{m}_batch"
            if not METHODS[m].fixed_step:  # the output grids
                for g in (f"{m}_grid", f"{m}_grid_batch"):
                    c[g], f[g] = f"{p}_{g}", f"{p}_f_{g}"
                if self.event_grid is not None:  # the grid with the events located
                    for g in (f"{m}_events", f"{m}_events_batch"):
                        c[g], f[g] = f"{p}_{g}", f"{p}_f_{g}"
        if self.scene.integrators:
            c["ode_strerror"] = f"{p}_ode_strerror"
        return {"c": c, "fortran": f}


@dataclass(frozen=True)
class VariationalContext(SceneContext):
    """The augmented system y = (x, Phi's and S's entries that can be
    nonzero), its rows documented by what they differentiate."""

    base: SceneContext | None = None

    @property
    def layout(self) -> Variational:
        assert self.base is not None and self.base.optimized.variational is not None
        return self.base.optimized.variational

    @property
    def nx_state(self) -> int:
        """The state's own size: y[0 .. nx_state) is x."""
        return len(self.states) - self.layout.nv

    @property
    def measured(self) -> int | None:
        """x alone with the scene's sensitivities.error = "state"."""
        return self.nx_state if self.layout.error == "state" else None

    @property
    def kinds(self) -> tuple[StateKind, ...]:
        """x's kinds, then Phi's and S's entries: magnitudes."""
        x = tuple(state_kind(s.name) for s in self.states[: self.nx_state])
        phi: list[StateKind] = ["magnitude"] * self.layout.nv
        return (*x, *phi)

    @property
    def state_rows(self) -> list[Row]:
        n, var = self.nx_state, self.layout
        x = [
            Row(i, s.name, *self.scene.unit_and_doc(s.name)) for i, s in enumerate(self.states[:n])
        ]
        return x + [
            Row(
                n + r,
                s.name,
                "",
                f"d {self.states[i].name} / d {var.columns[k]}(t0): Phi[{i}][{k}]",
            )
            for r, (s, (i, k)) in enumerate(zip(var.symbols, var.entries, strict=True))
        ]

    @cached_property
    def lu_blocks(self) -> Blocks | None:
        """The diagonal blocks of the augmented Jacobian: x's, then each
        column's of Phi; the variational part's reads of x are not
        factored but subtracted in the solve, once x's part is solved
        (symbolic.blocks.diagonal_blocks' coupled_from, Blocks.coupled)."""
        jac = self.optimized.jacobian
        return None if jac is None else diagonal_blocks(jac.outputs, self.nx, self.nx_state)

    @cached_property
    def jet(self) -> Jet | None:
        """The augmented rhs as elementary operations: x's groups as the
        scene's, and each column's entries of one row group as a group of
        their own (magnitudes), or none bounding the step (x measured alone)."""
        if not any(m.taylor for m in self.methods):
            return None
        n, var = self.nx_state, self.layout
        scales = state_scales([s.name for s in self.states[:n]])
        if self.measured is not None:
            scales += ((UNMEASURED, "magnitude"),) * var.nv
        else:
            scales += tuple((f"d {scales[i][0]} / d {var.columns[k]}", "magnitude")
                            for i, k in var.entries)  # fmt: skip
        return replace(decompose(self.optimized.rhs, self.states), scales=scales)


def versions() -> dict[str, str]:
    return {"gyrogen": gyrogen.__version__, "sympy": version("sympy")}


def build_id(scene: Scene) -> str:
    """Hash of the scene and the tool versions: which build a binary is from.
    A function of the scene alone, known before its unit is made."""
    text = json.dumps([scene.model_dump(mode="json"), versions()], sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def make_context(scene: Scene) -> SceneContext:
    eqs = specialize(scene)
    var = scene.sensitivities
    wrt, error = (var.wrt, var.error) if var is not None else ((), "all")
    jacobian = needs_jacobian(scene.integrators)
    return SceneContext(scene, eqs, optimize(eqs, jacobian, wrt, error))


def _vector_doc(v: Sequence[object] | str, keys: tuple[str, str, str], k: int) -> str:
    """A vector's components in A, or its p[] names (keys of rotor k) when runtime."""
    if v == "runtime":
        return ", ".join(f"p[{rotor_name(key, k)}]" for key in keys)
    return ", ".join(f"{float(x):.6g}" for x in v)  # type: ignore[arg-type]


def _gimbal_axes_doc(r: Rotor, k: int, at: str) -> list[str]:
    """A gimbal rotor's spin axis at gimbal angle 0 and its gimbal axis (as
    setup makes them when runtime), and its position at."""
    assert r.gimbal is not None
    if r.axes_at_runtime:
        spin = f"({_vector_doc(r.axis, AXIS, k)}) made perpendicular to g_g{k}, normalized"
        g_g = f"({_vector_doc(r.gimbal.axis, GIMBAL_AXIS, k)}) normalized"
    else:
        spin = f"({_vector_doc(r.spin_axis, AXIS, k)})"
        g_g = f"({_vector_doc(r.gimbal.unit_axis, GIMBAL_AXIS, k)})"
    return [
        f"Rotor B{k} on gimbal G{k}: spin axis g{k} = {spin} in A at gimbal angle 0,",
        f"  turned by gam{k} about the gimbal axis g_g{k} = {g_g} in A",
        f"  (g{k}(gam{k}) = cos(gam{k}) g{k}(0) + sin(gam{k}) g_g{k} x g{k}(0));",
        f"  B{k}* at ({at}) m from A*;",
    ]


def _gimbal_law_doc(gimbal: Gimbal, k: int) -> list[str]:
    """A gimbal's torque law u_g in words, its values or their p[] names, and
    its clamp (a line of its own)."""
    v = {key: f"p[{rotor_name(GIMBAL_KEYS[key], k)}]" if val == "runtime" else f"{val:g}"
         for key, val in gimbal.law().items()}  # fmt: skip
    law = {
        "none": "no gimbal torque",
        "constant": f"gimbal torque u_g = {v.get('T')} N m",
        "rate_servo": f"rate servo u_g = -k (gd{k} - rate_ref), k = {v.get('k')}, "
        f"rate_ref = {v.get('rate_ref')}",
        "table": f"gimbal torque u_g(t), piecewise linear through its table (torqueg_{k})",
    }[gimbal.torque]
    if gimbal.tau_max is None:
        return [f"  gimbal G{k}: {law}."]
    return [f"  gimbal G{k}: {law},", f"    |u_g| clamped to {gimbal.tau_max:g} N m."]


def _law_doc(law: dict[str, float | str], torque: str, k: int) -> str:
    """A rotor's torque law in words, its values or their p[] names."""
    v = {key: f"p[{key}_{k}]" if val == "runtime" else f"{val:g}" for key, val in law.items()}
    if torque == "constant":
        return f"motor torque T = {v['T']} N m"
    if torque == "speed_controller":
        return (f"speed controller T = -k (w{k} - g{k}.w_A - w_ref), k = {v['k']}, "
                f"w_ref = {v['w_ref']}")  # fmt: skip
    if torque == "table":
        return f"motor torque T(t), piecewise linear through its table (torque_{k})"
    return "no motor torque"
