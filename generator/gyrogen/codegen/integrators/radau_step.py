"""Radau IIA's step loop (radau5.f's RADCOR), described once: the Newton
iterations from the last step's collocation polynomial, their convergence
control, the error test and Hairer's step-size strategy with Gustafsson's
predictive controller, J and the factors kept while they serve."""

from __future__ import annotations

from gyrogen.codegen.integrators import driver, linear
from gyrogen.codegen.integrators import quaternion as euler_parameters
from gyrogen.codegen.integrators.common import (
    NE,
    NX,
    accepted,
    comp,
    dx,
    finite_state,
    h,
    i,
    locked,
    size,
    x,
    xnew,
)
from gyrogen.codegen.integrators.explicit import at
from gyrogen.codegen.integrators.radau import EPS, c, dot, each, matrix, pivots, t, y
from gyrogen.codegen.ir.nodes import (
    Bool,
    Break,
    Call,
    Comment,
    Const,
    Continue,
    Decl,
    E,
    For,
    Func,
    If,
    Int,
    Loop,
    Num,
    Row,
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
from gyrogen.symbolic.blocks import Blocks
from gyrogen.tableaus import Radau

V = {n: Var(n) for n in (
    "J e1 e2r e2i piv1 piv2 z1 z2 z3 w1 w2 w3 ak1 ak2 ak3 f0 fnew scal t0 t1 h_old h_new h_acc "
    "err_acc newton_tol err quot rate theta theta_old dyno dyno_old newt outcome "
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
             assign(v["scal"][i], Var("atol") + Var("rtol") * size(i, x))),
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
        assign(v["newton_tol"], fn("max", Num(ctl.newton_tol[0]) * EPS / Var("rtol"),
                                   fn("min", ctl.newton_tol[1], fn("sqrt", Var("rtol"))))),
        *driver.next_knot(knots),
        If(driver.final_step(knots), (assign(h, v["t1"] - t), assign(last, True))),
        *driver.knot_clip(knots, last),
        each(assign(v["scal"][i], Var("atol") + Var("rtol") * size(i, x))),
        Loop(tuple(loop)),
    )  # fmt: skip
    doubles = (
        "t h h_old h_new h_acc err_acc newton_tol err quot rate theta "
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
        f"{m.doc} Hairer's radau5.f strategy, with the error test at rtol and atol as",
        "given (radau5.f loosens them to 0.1 rtol^(2/3)); h_new/h = fac err^-1/4",
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


# Over SIMD lanes: one turn of m.name_integrate's loop on every lane, its
# branches as selections (gyrogen.codegen.ir.lanes). The Newton iterations
# are a loop whose turns go on while any lane iterates; E1 and E2 are the
# struct's lu, piv and e2r, e2i, piv2 (linear's LU over lanes), kept from
# step to step: a lane that refactors none keeps its own by selection.

L = {n: Var(n) for n in (
    "zs1 zs2 zs3 jn e1 e2rk e2ik piv2k eg span begun go fresh bad refac sing retry stop iter "
    "done cont fail ok0 take rej lock ok fin keep gamma_h alpha_h beta_h total norm again "
    "badf fresh0 code ending"
).split()}  # fmt: skip
LANE_ROWS = ("zs1", "zs2", "zs3", "w1", "w2", "w3", "ak1", "ak2", "ak3", "f0", "fnew", "scal", "eg")
LANE_BOOLS = ("ending", "first", "reject", "fresh_jac", "need_jac", "need_lu", "begun")
LANE_REALS = ("h_old", "h_acc", "err_acc", "rate", "theta", "theta_old", "dyno_old", "span")
STEP_BOOLS = ("go", "fresh", "bad", "refac", "sing", "retry", "stop", "iter", "done", "cont",
              "fail", "ok0", "take", "rej", "lock", "ok", "fin", "keep", "again", "badf",
              "fresh0")  # fmt: skip
STEP_REALS = ("gamma_h", "alpha_h", "beta_h", "total", "norm", "dyno", "thq", "predicted", "q",
              "theta_k", "err", "quot", "h_new", "gus",  "c1q", "c2q", "c3q")  # fmt: skip


def _any_nonfinite(flag: Var, values: Var, n: E) -> list[S]:
    """flag := flag or a NaN or Inf among values[0..n-1] (all_finite, over lanes)."""
    return [For("i", n, (assign(flag, or_(flag, not_(fn("finite", values[i])))),))]


def lanes_step(
    m: Method,
    quaternion: bool,
    blocks: Blocks,
    grid: bool | driver.Grid = False,
    knots: driver.Knots = (),
) -> Func:
    """m.name_step_lanes: one turn of m.name_integrate's loop on every lane,
    each branch a selection (a lane that stopped, whose E1 or E2 is singular
    or whose Newton iterations fail computes on and keeps nothing); its
    Newton iterations a loop while any lane iterates (a lane that converged
    or failed keeps its values); E1 and E2 factored on every lane when any
    lane needs them (each lane's own kept factors restored by selection),
    solved by linear's functions over lanes. With grid,
    m.name_grid_step_lanes (driver.passed, driver.reached); with events,
    m.name_events_step_lanes: the step counted, then driver.lane_events
    (which stops a lane at a terminal event or a full log), then x := xnew
    on the lanes still taken."""
    R, ctl = m.tableau, m.control
    assert isinstance(R, Radau) and isinstance(ctl, RadauControl)
    v, w = V, L
    c1, c2 = R.nodes[0], R.nodes[1]
    control = driver.Gustafsson(ctl)
    cd, go, last, first = w["code"], w["go"], w["ending"], v["first"]
    k0 = Row("k", Int(0))
    kk = Var("k")
    z2s, z3s = Var("z2"), Var("z3")  # the complex system's right-hand side and solution
    zs = [w["zs1"], w["zs2"], w["zs3"]]
    ws = [v["w1"], v["w2"], v["w3"]]
    avars = [v["a1"], v["a2"], v["a3"]]
    a: list[E] = list(avars)
    t1 = Var("t1")
    row = driver.BASE + driver.G
    nx2 = Const("NX2")
    # the entries of J and the factors the LU reads and writes (linear.shift's)
    nx = len(blocks.end)
    stored = tuple(r * nx + col for r, cols in enumerate(blocks.stored) for col in cols)
    entries, at_e = Int(len(stored)), Var("stored")[Var("e")]

    def rejected(when: E) -> list[S]:
        return [
            driver.count("rejected", sel(when, Int(1), Int(0))),
            assign(v["reject"], sel(when, True, v["reject"])),
            assign(last, sel(when, False, last)),
        ]

    fresh0 = w["fresh0"]
    start: list[S] = [
        Comment("a lane's first turn: a last step from t0 (m.name_integrate's start)"),
        assign(go, cmp(cd, "<", 0)),
        assign(fresh0, and_(go, not_(w["begun"]))),
        *driver.next_knot(knots),
        assign(h, sel(and_(fresh0, driver.final_step(knots)), t1 - t, h)),
        assign(last, sel(fresh0, driver.final_step(knots), last)),
        *driver.knot_clip(knots, last, fresh0),
        assign(w["begun"], sel(go, True, w["begun"])),
        each(assign(v["scal"][i], Var("atol") + Var("rtol") * size(i, x))),
    ]
    fresh, bad, jn = w["fresh"], w["bad"], w["jn"]
    jacobian: list[S] = [
        assign(fresh, and_(go, v["need_jac"])),
        assign(bad, False),
        If(fresh, (
            Call("jac", (t, x, c, jn)),
            driver.count("jac_calls", 1),
            *_any_nonfinite(bad, jn, nx2),
            For("e", entries, (assign(v["J"][at_e], jn[at_e]),)),
            assign(cd, sel(bad, driver.ERR_NONFINITE, cd)),
            assign(v["fresh_jac"], True),
            assign(v["need_jac"], False),
            assign(v["need_lu"], True),
        ), own=("jn",)),
        assign(go, cmp(cd, "<", 0)),
        assign(cd, sel(go, driver.stop_code(v["nonfinite"]), cd)),
        assign(go, cmp(cd, "<", 0)),
    ]  # fmt: skip
    need, sing, retry, stop = w["refac"], w["sing"], w["retry"], w["stop"]
    lu, piv, e2r, e2i, piv2 = Var("lu"), Var("piv"), Var("e2r"), Var("e2i"), Var("piv2")
    e1, e2rk, e2ik, piv1, piv2k = w["e1"], w["e2rk"], w["e2ik"], v["piv1"], w["piv2k"]
    g_, a_, b_ = w["gamma_h"], w["alpha_h"], w["beta_h"]
    J = v["J"]
    diag = i * NX + i
    factors: list[S] = [
        assign(g_, Num(R.gamma) / h),
        assign(a_, Num(R.alpha) / h),
        assign(b_, Num(R.beta) / h),
        assign(need, and_(go, v["need_lu"])),
        assign(sing, False),
        If(need, (
            Comment("each lane's kept factors, then E1 and E2 for this h on every lane"),
            For("e", entries, (assign(e1[at_e], lu[at_e]), assign(e2rk[at_e], e2r[at_e]),
                               assign(e2ik[at_e], e2i[at_e]))),
            each(assign(piv1[i], piv[i]), assign(piv2k[i], piv2[i])),
            For("e", entries, (assign(lu[at_e], -J[at_e]), assign(e2r[at_e], -J[at_e]),
                               assign(e2i[at_e], 0.0))),
            each(assign(lu[diag], g_ - J[diag]), assign(e2r[diag], a_ - J[diag]),
                 assign(e2i[diag], b_)),
            Call("lu_decompose", (), "E1's LU on every lane, each its own pivots"),
            Call("lu_decompose_complex", (), "E2's"),
            assign(sing, linear.ZERO_PIVOT),
            driver.count("decompositions", 1),
            Comment("a lane that refactors none: its kept factors back"),
            For("e", entries, (assign(lu[at_e], sel(need, lu[at_e], e1[at_e])),
                               assign(e2r[at_e], sel(need, e2r[at_e], e2rk[at_e])),
                               assign(e2i[at_e], sel(need, e2i[at_e], e2ik[at_e])))),
            each(assign(piv[i], sel(need, piv[i], piv1[i])),
                 assign(piv2[i], sel(need, piv2[i], piv2k[i]))),
        ), own=("e1", "e2rk", "e2ik", "piv1", "piv2k", "lu", "e2r", "e2i", "piv", "piv2")),
        Comment("a singular E1 or E2: so many in a row stop; else h shrunk"),
        assign(retry, and_(need, sing)),
        *driver.singular_selected(v["singular"], retry, need, cd, ctl.singular_tries),
        assign(stop, and_(retry, cmp(v["singular"], "==", ctl.singular_tries))),
        assign(retry, and_(retry, not_(stop))),
        *rejected(retry),
        assign(h, sel(retry, h * Num(ctl.newton_shrink), h)),
        assign(v["need_jac"], sel(retry, not_(v["fresh_jac"]), v["need_jac"])),
        assign(v["need_lu"], sel(and_(need, not_(sing)), False, v["need_lu"])),
        assign(go, and_(go, not_(and_(need, sing)))),
        assign(driver.stat("h"), sel(go, h, driver.stat("h"))),
    ]  # fmt: skip

    def extrapolated(cq: Var) -> E:
        inner = v["ak2"][i] + (cq + Num(1.0 - c1)) * v["ak3"][i]
        return cq * (v["ak1"][i] + (cq + Num(1.0 - c2)) * inner)

    newt, dyno, theta, rate, outcome = v["newt"], v["dyno"], v["theta"], v["rate"], v["outcome"]
    begin_newton: list[S] = [
        Comment("the Newton iterations start from the last step's collocation polynomial"),
        assign(v["c3q"], h / v["h_old"]),
        assign(v["c1q"], Num(c1) * v["c3q"]),
        assign(v["c2q"], Num(c2) * v["c3q"]),
        each(
            *(assign(avars[j], extrapolated(q)) for j, q in
              enumerate((v["c1q"], v["c2q"], v["c3q"]))),
            *(assign(zs[j][i], sel(go, sel(first, 0.0, a[j]), zs[j][i])) for j in range(3)),
            *(assign(ws[j][i], sel(go, sel(first, 0.0, dot(R.ti[j], a)), ws[j][i]))
              for j in range(3)),
            local=("a1", "a2", "a3"),
        ),
        assign(outcome, 0),
        assign(rate, sel(go, fn("pow", fn("max", rate, EPS), ctl.rate_power), rate)),
        assign(theta, sel(go, ctl.jacobian_reuse, theta)),
        assign(newt, 0),
        assign(w["iter"], go),
        assign(w["done"], False),
    ]  # fmt: skip
    k_slow, q, theta_k = 4 + ctl.newton_max - 1, v["q"], v["theta_k"]
    total, iter_, done, cont = w["total"], w["iter"], w["done"], w["cont"]
    s1, s2, s3 = Var("s1"), Var("s2"), Var("s3")
    contraction: list[S] = [
        assign(v["thq"], dyno / v["dyno_old"]),
        assign(theta, sel(cmp(newt, "==", 2), v["thq"], fn("sqrt", v["thq"] * v["theta_old"]))),
        assign(v["theta_old"], v["thq"]),
        If(not_(cmp(theta, "<", ctl.newton_diverged)), (assign(outcome, 2),)),
        If(cmp(theta, "<", ctl.newton_diverged), (
            assign(rate, theta / (Num(1.0) - theta)),
            assign(theta_k, 1.0),
            For("j", Int(ctl.newton_max - 1),
                (assign(theta_k, sel(cmp(Var("j"), ">=", newt), theta_k * theta, theta_k)),)),
            assign(v["predicted"], rate * dyno * theta_k / v["newton_tol"]),
            If(cmp(v["predicted"], ">=", 1.0), (
                assign(q, fn("max", ctl.newton_slow[1],
                             fn("min", ctl.newton_slow[2], v["predicted"]))),
                assign(h, h * (Num(ctl.newton_slow[0])
                               * fn("pow", q, Num(-1.0) / (Int(k_slow) - newt)))),
                assign(outcome, 1),
            )),
        )),
    ]  # fmt: skip
    iteration = Loop((
        assign(iter_, and_(iter_, cmp(outcome, "==", 0), not_(done))),
        If(not_(iter_), (Break(),)),
        If(iter_, (
            each(assign(y[i], x[i] + zs[0][i])),
            Call("rhs", (at(R.nodes[0]), y, c, k0)),
            each(assign(y[i], x[i] + zs[1][i])),
            Call("rhs", (at(R.nodes[1]), y, c, z2s)),
            each(assign(y[i], x[i] + zs[2][i])),
            Call("rhs", (t + h, y, c, z3s)),
            each(
                assign(avars[0], kk[0, i]), assign(avars[1], z2s[i]), assign(avars[2], z3s[i]),
                assign(kk[0, i], dot(R.ti[0], a) - g_ * ws[0][i]),
                assign(z2s[i], dot(R.ti[1], a) - a_ * ws[1][i] + b_ * ws[2][i]),
                assign(z3s[i], dot(R.ti[2], a) - a_ * ws[2][i] - b_ * ws[1][i]),
                local=("a1", "a2", "a3"),
            ),
            Call("lu_solve", (Int(0),)),
            Call("lu_solve_complex", ()),
            assign(total, 0.0),
            each(
                assign(s1, kk[0, i] / v["scal"][i]), assign(s2, z2s[i] / v["scal"][i]),
                assign(s3, z3s[i] / v["scal"][i]),
                assign(total, total + (s1 * s1 + s2 * s2 + s3 * s3)),
                local=("s1", "s2", "s3"),
            ),
            assign(dyno, fn("sqrt", total / (Int(3) * NX))),
            driver.count("rhs_calls", 3),
            inc(newt, 1),
            assign(bad, not_(fn("finite", dyno))),
            If(bad, (assign(v["nonfinite"], True), assign(outcome, 2))),
            If(and_(not_(bad), cmp(newt, ">", 1), cmp(newt, "<", ctl.newton_max)),
               tuple(contraction)),
            assign(cont, cmp(outcome, "==", 0)),
            If(cont, (
                assign(v["dyno_old"], fn("max", dyno, EPS)),
                each(
                    assign(avars[0], ws[0][i] + kk[0, i]), assign(avars[1], ws[1][i] + z2s[i]),
                    assign(avars[2], ws[2][i] + z3s[i]),
                    *(assign(ws[j][i], a[j]) for j in range(3)),
                    *(assign(zs[j][i], dot(R.t[j], a)) for j in range(3)),
                    local=("a1", "a2", "a3"),
                ),
            )),
            assign(done, and_(cont, not_(cmp(rate * dyno, ">", v["newton_tol"])))),
            If(and_(cont, not_(done), cmp(newt, ">=", ctl.newton_max)), (assign(outcome, 2),)),
        ), own=("k", "z2", "z3")),
    ))  # fmt: skip
    ok0, norm, again, err = w["ok0"], w["norm"], w["again"], v["err"]
    eg = w["eg"]

    def rms() -> list[S]:
        return [
            assign(total, 0.0),
            For("i", NE, (assign(total, total + (kk[0, i] / v["scal"][i])
                                    * (kk[0, i] / v["scal"][i])),), vector=True),
            assign(norm, fn("sqrt", total / NE)),
        ]  # fmt: skip

    badf = w["badf"]
    test: list[S] = [
        Comment("the error test (radau5's error estimate)"),
        assign(ok0, and_(go, cmp(outcome, "==", 0))),
        each(assign(eg[i], dot(R.e, [zs[0][i], zs[1][i], zs[2][i]]) / h),
             assign(kk[0, i], v["f0"][i] + eg[i])),
        Call("lu_solve", (Int(0),)),
        *rms(),
        assign(again, and_(ok0, cmp(norm, ">=", 1.0), or_(first, v["reject"]))),
        If(again, (
            each(assign(y[i], x[i] + kk[0, i])),
            Call("rhs", (t, y, c, k0)),
            driver.count("rhs_calls", 1),
            each(assign(kk[0, i], kk[0, i] + eg[i])),
            Call("lu_solve", (Int(0),)),
            *rms(),
        ), own=("k",)),
        assign(err, sel(cmp(norm, "<", ctl.err_min), ctl.err_min, norm)),
        each(assign(dx[i], zs[2][i] - comp[i]), assign(xnew[i], x[i] + dx[i])),
        assign(w["fin"], and_(ok0, cmp(err, "<", 1.0), not_(last))),
        assign(badf, False),
        If(w["fin"], (
            Call("rhs", (t + h, xnew, c, v["fnew"]), "where the next step starts"),
            driver.count("rhs_calls", 1),
            *_any_nonfinite(badf, v["fnew"], NX),
        )),
        assign(bad, sel(w["fin"], badf, not_(fn("finite", err)))),
        *_any_nonfinite(bad, xnew, NX),
        *([assign(bad, or_(bad, euler_parameters.lost(euler_parameters.norm_of(xnew))))]
          if quaternion else []),
        assign(v["nonfinite"], sel(ok0, bad, v["nonfinite"])),
        assign(outcome, sel(and_(ok0, bad), 2, outcome)),
    ]  # fmt: skip
    fail, take, rej, lock, ok = w["fail"], w["take"], w["rej"], w["lock"], w["ok"]
    quot, h_new, keep, fin = v["quot"], v["h_new"], w["keep"], w["fin"]
    fac = fn("min", ctl.safety, Num(ctl.safety * (1 + 2 * ctl.newton_max))
             / (newt + Int(2 * ctl.newton_max)))  # fmt: skip
    kept = and_(cmp(theta, "<=", ctl.jacobian_reuse), cmp(h_new, ">=", Num(ctl.keep_h[0]) * h),
                cmp(h_new, "<=", Num(ctl.keep_h[1]) * h))  # fmt: skip
    kept = and_(kept, not_(driver.reaches_knot())) if knots else kept
    interpolant: list[S] = [
        assign(v["h_old"], h),
        each(
            assign(v["ak"], (zs[1][i] - zs[0][i]) / Num(c2 - c1)),
            assign(v["ak1"][i], (zs[2][i] - zs[1][i]) / Num(1.0 - c2)),
            assign(v["ak2"][i], (v["ak1"][i] - v["ak"]) / Num(1.0 - c1)),
            assign(v["ak3"][i], v["ak2"][i] - (v["ak"] - zs[0][i] / Num(c1)) / Num(c2)),
            local=("ak",),
        ),
    ]
    refactor = [assign(v["need_lu"], True), assign(v["need_jac"], not_(v["fresh_jac"]))]
    control_: list[S] = [
        Comment("Newton failed or too slow, or a NaN or Inf: rejected"),
        assign(fail, and_(go, cmp(outcome, "!=", 0))),
        *rejected(fail),
        assign(h, sel(and_(fail, cmp(outcome, "==", 2)), h * Num(ctl.newton_shrink), h)),
        If(fail, tuple(refactor)),
        assign(go, and_(go, not_(fail))),
        assign(quot, control.quotient(err, fac), "h_new = h / quot"),
        assign(h_new, h / quot),
        assign(take, and_(go, cmp(err, "<", 1.0))),
        assign(rej, and_(go, not_(cmp(err, "<", 1.0)))),
        assign(lock, Bool(False) if quaternion else locked(x, xnew)),
        assign(ok, and_(take, not_(lock))),
        assign(first, sel(ok, False, first)),
        *control.predictive_selected(ok, quot, err),
        assign(h_new, h / quot),
        If(ok, tuple(interpolant)),
        *(_accepted(R, quaternion, grid, ok, rej, last, cd, row)),
        *(driver.reached(row, ok) if grid else []),
        assign(cd, driver.ended(and_(take, lock), ok, last, cd)),
        Comment("after an accepted step that is not the last: the next h, J and factors"),
        assign(cont, and_(ok, not_(last))),
        If(cont, (each(assign(v["f0"][i], v["fnew"][i])), assign(v["fresh_jac"], False))),
        assign(h_new, fn("min", h_new, w["span"])),
        assign(h_new, sel(v["reject"], fn("min", h_new, h), h_new)),
        assign(v["reject"], sel(cont, False, v["reject"])),
        *driver.next_knot(knots),
        assign(fin, driver.final_step(knots, h_new)),
        assign(keep, and_(not_(fin), kept)),
        assign(h, sel(cont, sel(fin, t1 - t, sel(keep, h, h_new)), h)),
        assign(last, sel(and_(cont, fin), True, last)),
        *driver.knot_clip(knots, last, and_(cont, not_(fin))),
        assign(v["need_jac"], sel(and_(cont, not_(keep)), cmp(theta, ">", ctl.jacobian_reuse),
                                  v["need_jac"])),
        assign(v["need_lu"], sel(and_(cont, not_(keep)), True, v["need_lu"])),
        Comment("a rejected step"),
        assign(v["reject"], sel(rej, True, v["reject"])),
        assign(last, sel(rej, False, last)),
        assign(h, sel(rej, sel(first, h * Num(ctl.first_reject), h_new), h)),
        If(rej, tuple(refactor)),
    ]  # fmt: skip
    body = (*start, *jacobian, *factors, *begin_newton, iteration, *test, *control_)
    zero = Num(0.0)
    tolerances = (Decl("newton_tol", "double"),)
    head = (
        assign(v["newton_tol"], fn("max", Num(ctl.newton_tol[0]) * EPS / Var("rtol"),
                                   fn("min", ctl.newton_tol[1], fn("sqrt", Var("rtol"))))),
    )  # fmt: skip
    body = (*head, *body)
    locals_ = (
        *tolerances,
        *(Decl(n, "bool", (), "inout", zero) for n in STEP_BOOLS),
        *(Decl(n, "double", (), "inout", zero) for n in STEP_REALS),
        *(Decl(n, "int", (), "inout", zero) for n in ("newt", "outcome")),
        *driver.knot_locals(knots),
        *(scalar("norm", "inout") for _ in range(int(quaternion))),
        Decl("stored", "int", (len(stored),), values=stored),
    )
    return driver.step_lanes(m, body, locals_, grid)


def _accepted(R: Radau, quaternion: bool, grid: bool | driver.Grid, ok: Var, rej: Var,
              last: Var, cd: Var, row: E) -> list[S]:  # fmt: skip
    """A turn's acceptance over lanes: the grid times the step passes, x :=
    xnew and the step counted; with events, the step counted first (its
    start and size kept, driver.grid_step), then its events (a stop clears
    ok), then x := xnew."""
    t1 = Var("t1")
    if isinstance(grid, driver.Grid) and grid.events:
        told, hs = Var("told"), Var("hs")
        return [
            *driver.grid_step(t, h),
            *driver.counted(ok, rej, last),
            *driver.lane_events(grid, collocation(R), ok, cd, t, told, hs, row),
            If(ok, tuple(accepted(quaternion))),
        ]
    passed = driver.passed(ok, collocation(R), sel(last, t1, t + h), t, h, row) if grid else []
    return [*passed, If(ok, tuple(accepted(quaternion))), *driver.counted(ok, rej, last)]


def lane_state(m: Method) -> list[Decl]:
    """What struct lanes holds for m per lane, beyond a pair's."""
    square = [matrix(n, "inout") for n in ("J", "jn", "e1", "e2rk", "e2ik")]
    square += [*linear.lanes_state(), *linear.lanes_state_complex()]
    square += [pivots("piv1", "inout"), pivots("piv2k", "inout")]
    rows = [arr(n, "inout") for n in LANE_ROWS]
    values = [Decl(n, "bool", (), "inout") for n in LANE_BOOLS]
    values += [scalar(n, "inout") for n in LANE_REALS] + [Decl("singular", "int", (), "inout")]
    stats = [Decl(f"stats.{n}", "long", (), "inout") for n in ("jac_calls", "decompositions")]
    return [*square, *rows, *values, *stats, Decl("k", "double", (1, "NX"), "inout")]


def lane_start(m: Method) -> list[S]:
    """A lane's values at t0 beyond common.start_state (m.name_integrate's
    start; its last step from t0 is the first turn's, begun)."""
    ctl = m.control
    assert isinstance(ctl, RadauControl)
    v = V
    return [
        *(assign(v[n], 1.0) for n in ("h_old", "rate", "theta_old", "dyno_old")),
        *driver.Gustafsson(ctl).start(),
        *(assign(v[n], val) for n, val in (("first", True), ("reject", False),
          ("fresh_jac", False), ("need_jac", True), ("need_lu", True))),
        assign(L["begun"], False),
        assign(L["ending"], False),
        assign(v["singular"], 0),
        assign(L["span"], Var("t1") - Var("t0")),
        each(assign(v["ak1"][i], 0.0), assign(v["ak2"][i], 0.0), assign(v["ak3"][i], 0.0)),
    ]  # fmt: skip


__all__ = ["integrate", "lane_start", "lane_state", "lanes_step"]
