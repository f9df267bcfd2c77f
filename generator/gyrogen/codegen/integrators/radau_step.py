"""Radau IIA's step loop (radau5.f's RADCOR), described once: the Newton
iterations from the last step's collocation polynomial, their convergence
control, the error test and Hairer's step-size strategy with Gustafsson's
predictive controller, J and the factors kept while they serve."""

from __future__ import annotations

from gyrogen.codegen.integrators import driver
from gyrogen.codegen.integrators.common import (
    comp,
    dx,
    finite_state,
    h,
    i,
    size,
    x,
    xnew,
)
from gyrogen.codegen.integrators.radau import EPS, c, dot, each, matrix, pivots, t
from gyrogen.codegen.ir.nodes import (
    Break,
    Comment,
    Continue,
    Decl,
    E,
    For,
    Func,
    If,
    Int,
    Loop,
    Num,
    S,
    Var,
    and_,
    arr,
    assign,
    cmp,
    fn,
    inc,
    not_,
    or_,
    sel,
)
from gyrogen.codegen.ir.nodes import real as scalar
from gyrogen.methods import Method, RadauControl
from gyrogen.tableaus import Radau

V = {n: Var(n) for n in (
    "J e1 e2r e2i piv1 piv2 z1 z2 z3 w1 w2 w3 ak1 ak2 ak3 f0 fnew scal t0 t1 h_old h_new h_acc "
    "err_acc rtol_e atol_e newton_tol err quot rate theta theta_old dyno dyno_old newt outcome "
    "last first reject fresh_jac need_jac need_lu singular nonfinite start thq predicted q gus "
    "ak c1q c2q c3q a1 a2 a3 theta_k"
).split()}  # fmt: skip


def collocation(R: Radau) -> driver.Interpolant:
    """radau5.f's CONTR5: from the step's end, s = (t - t_new) / h in [-1, 0],
    xnew + s (ak1 + (s - c2 + 1) (ak2 + (s - c1 + 1) ak3)): the collocation
    polynomial accepted() keeps for the next Newton iterations (order 3 at
    any point of the step; the step itself is of order 5)."""
    c1, c2 = R.nodes[0], R.nodes[1]

    def value(s: E, i: E) -> E:
        inner = V["ak2"][i] + (s + Num(1.0 - c1)) * V["ak3"][i]
        return xnew[i] + s * (V["ak1"][i] + (s + Num(1.0 - c2)) * inner)

    return driver.Interpolant((), driver.by_state(value), at_end=True)


def integrate(
    m: Method, quaternion: bool, grid: bool | driver.Grid = False, knots: driver.Knots = ()
) -> Func:
    """m.name_integrate, or with grid m.name_grid (the states at the grid's
    times, from the collocation polynomial); knots: the table times a step
    ends on (an h kept for its LU too)."""
    R, ctl = m.tableau, m.control
    assert isinstance(R, Radau) and isinstance(ctl, RadauControl)
    v = V
    c1, c2 = R.nodes[0], R.nodes[1]
    control = driver.Gustafsson(ctl)
    rejected: list[S] = [*driver.rejected(v["reject"]), assign(v["last"], False)]
    refactor = [assign(v["need_lu"], True), assign(v["need_jac"], not_(v["fresh_jac"]))]
    jac: list[S] = [
        *driver.jacobian(v["J"]),
        assign(v["fresh_jac"], True),
        assign(v["need_jac"], False),
        assign(v["need_lu"], True),
    ]
    factors = (v["J"], h, v["e1"], v["piv1"], v["e2r"], v["e2i"], v["piv2"])
    lu: list[S] = [
        driver.count("decompositions", 1),
        If(fn(f"{m.name}_factor", *factors), (
            *driver.singular_stop(v["singular"], ctl.singular_tries),
            *rejected,
            assign(h, h * Num(ctl.newton_shrink)),
            assign(v["need_jac"], not_(v["fresh_jac"])),
            Continue(),
        )),
        assign(v["singular"], 0),
        assign(v["need_lu"], False),
    ]  # fmt: skip

    def extrapolated(cq: Var) -> object:
        inner = v["ak2"][i] + (cq + Num(1.0 - c1)) * v["ak3"][i]
        return cq * (v["ak1"][i] + (cq + Num(1.0 - c2)) * inner)

    avars = [v["a1"], v["a2"], v["a3"]]
    a: list[E] = list(avars)
    z, w = [v["z1"], v["z2"], v["z3"]], [v["w1"], v["w2"], v["w3"]]
    start_newton: list[S] = [
        Comment("the Newton iterations start from the last step's collocation polynomial"),
        If(v["first"], (each(*(assign(u[i], 0.0) for u in (*z, *w))),), (
            assign(v["c3q"], h / v["h_old"]),
            assign(v["c1q"], Num(c1) * v["c3q"]),
            assign(v["c2q"], Num(c2) * v["c3q"]),
            each(
                *(assign(avars[k], extrapolated(q)) for k, q in  # type: ignore[arg-type]
                  enumerate((v["c1q"], v["c2q"], v["c3q"]))),
                *(assign(z[k][i], a[k]) for k in range(3)),
                *(assign(w[k][i], dot(R.ti[k], a)) for k in range(3)),
                local=("a1", "a2", "a3"),
            ),
        )),
    ]  # fmt: skip
    newt, dyno, theta, rate = v["newt"], v["dyno"], v["theta"], v["rate"]
    k_slow, q = 4 + ctl.newton_max - 1, v["q"]
    theta_k = v["theta_k"]
    theta_to_k: list[S] = [  # theta^(newton_max - 1 - newt) by products: 0 to 4 of them
        assign(theta_k, 1.0),
        For("k", Int(ctl.newton_max - 1), (assign(theta_k, theta_k * theta),), start=newt),
    ]
    slow: list[S] = [
        assign(q, fn("max", ctl.newton_slow[1], fn("min", ctl.newton_slow[2], v["predicted"]))),
        assign(h, h * (Num(ctl.newton_slow[0]) * fn("pow", q, Num(-1.0) / (Int(k_slow) - newt)))),
        assign(v["outcome"], 1),
        Break(),
    ]  # fmt: skip
    contraction: list[S] = [
        assign(v["thq"], dyno / v["dyno_old"]),
        assign(theta, sel(cmp(newt, "==", 2), v["thq"], fn("sqrt", v["thq"] * v["theta_old"]))),
        assign(v["theta_old"], v["thq"]),
        If(not_(cmp(theta, "<", ctl.newton_diverged)), (assign(v["outcome"], 2), Break())),
        assign(rate, theta / (Num(1.0) - theta)),
        *theta_to_k,
        assign(v["predicted"], rate * dyno * theta_k / v["newton_tol"]),
        If(cmp(v["predicted"], ">=", 1.0), tuple(slow)),
    ]  # fmt: skip
    nargs = (t, h, x, c, v["e1"], v["piv1"], v["e2r"], v["e2i"], v["piv2"], v["scal"], *z, *w)
    iterate = Loop((
        If(cmp(newt, ">=", ctl.newton_max), (assign(v["outcome"], 2), Break())),
        assign(dyno, fn(f"{m.name}_newton", *nargs)),
        driver.count("rhs_calls", 3),
        inc(newt, 1),
        If(not_(fn("finite", dyno)), (assign(v["nonfinite"], True), assign(v["outcome"], 2),
                                      Break())),
        If(and_(cmp(newt, ">", 1), cmp(newt, "<", ctl.newton_max)), tuple(contraction)),
        assign(v["dyno_old"], fn("max", dyno, EPS)),
        each(
            *(assign(avars[k], w[k][i] + z[k][i]) for k in range(3)),
            *(assign(w[k][i], a[k]) for k in range(3)),
            *(assign(z[k][i], dot(R.t[k], a)) for k in range(3)),
            local=("a1", "a2", "a3"),
        ),
        If(not_(cmp(rate * dyno, ">", v["newton_tol"])), (Break(),)),
    ))  # fmt: skip
    err, quot, h_new, last = v["err"], v["quot"], v["h_new"], v["last"]
    eargs = (t, h, x, c, v["f0"], v["e1"], v["piv1"], v["scal"], *z,
             or_(v["first"], v["reject"]), Var("stats"))  # fmt: skip
    test: list[S] = [
        assign(err, fn(f"{m.name}_error", *eargs)),
        each(assign(dx[i], z[2][i] - comp[i]), assign(xnew[i], x[i] + dx[i])),
        If(and_(cmp(err, "<", 1.0), not_(last)), tuple(driver.next_f(v["fnew"], v["nonfinite"])),
           (assign(v["nonfinite"], not_(fn("finite", err))),)),
        assign(v["nonfinite"], or_(v["nonfinite"], not_(finite_state(xnew, quaternion)))),
        If(v["nonfinite"], (assign(v["outcome"], 2),)),
    ]  # fmt: skip
    fac = fn("min", ctl.safety, Num(ctl.safety * (1 + 2 * ctl.newton_max))
             / (newt + Int(2 * ctl.newton_max)))  # fmt: skip
    ak = v["ak"]
    keep = and_(cmp(theta, "<=", ctl.jacobian_reuse), cmp(h_new, ">=", Num(ctl.keep_h[0]) * h),
                cmp(h_new, "<=", Num(ctl.keep_h[1]) * h))  # fmt: skip
    kept = and_(keep, not_(driver.reaches_knot())) if knots else keep  # h and its LU kept
    interpolant: list[S] = [  # the collocation polynomial, the next Newton iterations' start
        assign(v["h_old"], h),
        each(
            assign(ak, (z[1][i] - z[0][i]) / Num(c2 - c1)),
            assign(v["ak1"][i], (z[2][i] - z[1][i]) / Num(1.0 - c2)),
            assign(v["ak2"][i], (v["ak1"][i] - ak) / Num(1.0 - c1)),
            assign(v["ak3"][i], v["ak2"][i] - (ak - z[0][i] / Num(c1)) / Num(c2)),
            local=("ak",),
        ),
    ]
    predictive = control.predictive(quot, err, then=(assign(h_new, h / quot),))
    accept: list[S] = [
        *driver.accepted(quaternion, last, [assign(v["first"], False), *predictive], interpolant,
                         collocation(R) if grid else None, grid),
        each(assign(v["f0"][i], v["fnew"][i]),
             assign(v["scal"][i], v["atol_e"] + v["rtol_e"] * size(i, x))),
        assign(v["fresh_jac"], False),
        assign(h_new, fn("min", h_new, v["t1"] - v["t0"])),
        If(v["reject"], (assign(h_new, fn("min", h_new, h)),)),
        assign(v["reject"], False),
        *driver.next_knot(knots),
        If(driver.final_step(knots, h_new), (assign(h, v["t1"] - t), assign(last, True)), (
            If(kept, (Continue(),), (assign(h, h_new),)), *driver.knot_clip(knots, last))),
        assign(v["need_lu"], True),
        assign(v["need_jac"], cmp(theta, ">", ctl.jacobian_reuse)),
    ]  # fmt: skip
    loop: list[S] = [
        If(v["need_jac"], tuple(jac)),
        *driver.stop_tests(v["nonfinite"]),
        If(v["need_lu"], tuple(lu)),
        assign(driver.stat("h"), h),
        *start_newton,
        Comment("outcome: 0 converged, 1 too slowly (h reduced), 2 failed"),
        assign(v["outcome"], 0),
        assign(rate, fn("pow", fn("max", rate, EPS), ctl.rate_power)),
        assign(theta, ctl.jacobian_reuse),
        assign(newt, 0),
        iterate,
        If(cmp(v["outcome"], "==", 0), tuple(test)),
        If(cmp(v["outcome"], "!=", 0), (
            *rejected,
            If(cmp(v["outcome"], "==", 2), (assign(h, h * Num(ctl.newton_shrink)),)),
            *refactor,
            Continue(),
        )),
        assign(quot, control.quotient(err, fac), "h_new = h / quot"),
        assign(h_new, h / quot),
        If(cmp(err, "<", 1.0), tuple(accept), (
            *rejected,
            assign(h, sel(v["first"], h * Num(ctl.first_reject), h_new)),
            *refactor,
        )),
    ]  # fmt: skip
    body = (
        *driver.started(m, v["f0"], v["start"], grid),
        assign(t, v["t0"]),
        *(assign(v[n], 1.0) for n in ("h_old", "rate", "theta_old", "dyno_old")),
        *control.start(),
        *(assign(v[n], val) for n, val in (("last", False), ("first", True), ("reject", False),
          ("fresh_jac", False), ("need_jac", True), ("need_lu", True), ("nonfinite", False))),
        assign(v["singular"], 0),
        each(assign(comp[i], 0.0), assign(v["ak1"][i], 0.0), assign(v["ak2"][i], 0.0),
             assign(v["ak3"][i], 0.0)),
        assign(v["rtol_e"], Num(ctl.tol_factor) * fn("pow", Var("rtol"), ctl.tol_power)),
        assign(v["atol_e"], v["rtol_e"] * (Var("atol") / Var("rtol"))),
        assign(v["newton_tol"], fn("max", Num(ctl.newton_tol[0]) * EPS / v["rtol_e"],
                                   fn("min", ctl.newton_tol[1], fn("sqrt", v["rtol_e"])))),
        *driver.next_knot(knots),
        If(driver.final_step(knots), (assign(h, v["t1"] - t), assign(last, True))),
        *driver.knot_clip(knots, last),
        each(assign(v["scal"][i], v["atol_e"] + v["rtol_e"] * size(i, x))),
        Loop(tuple(loop)),
    )  # fmt: skip
    doubles = (
        "t h h_old h_new h_acc err_acc rtol_e atol_e newton_tol err quot rate theta "
        "theta_old dyno dyno_old thq predicted q gus c1q c2q c3q theta_k"
    ).split()
    bools = "last first reject fresh_jac need_jac need_lu nonfinite".split()
    locals_ = (
        *(matrix(n, "inout") for n in ("J", "e1", "e2r", "e2i")),
        *(arr(n, "inout") for n in ("z1 z2 z3 w1 w2 w3 ak1 ak2 ak3 f0 fnew scal xnew dx "
                                     "comp").split()),
        pivots("piv1", "inout"), pivots("piv2", "inout"),
        *(scalar(n, "inout") for n in doubles), *(Decl(n, "bool") for n in bools),
        *(Decl(n, "int") for n in ("newt", "outcome", "singular", "start")),
        *(driver.grid_locals(body, grid) if grid else ()),
        *driver.knot_locals(knots),
    )  # fmt: skip
    doc = (
        f"{m.doc} Hairer's radau5.f strategy: the error test's tolerances are",
        f"rtol' = {ctl.tol_factor:g} rtol^(2/3) and atol' = rtol' atol/rtol;",
        "h_new/h = fac err^-1/4",
        f"within [{ctl.facmin:g}, {ctl.facmax:g}] (fac = {ctl.safety:g}, less after many Newton"
        " iterations), and Gustafsson's predictive controller after an accepted step.",
        f"J is kept while the Newton iterations contract by <= {ctl.jacobian_reuse:g} a step, and",
        f"h, E1 and E2 too while h_new/h is within [{ctl.keep_h[0]:g}, {ctl.keep_h[1]:g}]. Newton"
        f" iterations that diverge, take more than {ctl.newton_max}, or meet a NaN or Inf",
        f"retry with h halved (slow ones with a smaller h); a singular E1 or E2 too,"
        f" {ctl.singular_tries} times in a row at most.",
        *driver.knot_doc(knots),
    )
    if grid:
        return Func(
            f"{m.name}_{driver.variant(grid)}",
            driver.grid_params(grid),
            body,
            "int",
            locals_,
            (*doc, *driver.GRID_DOC),
        )
    return Func(f"{m.name}_integrate", driver.PARAMS, body, "int", locals_, doc)


__all__ = ["integrate"]
