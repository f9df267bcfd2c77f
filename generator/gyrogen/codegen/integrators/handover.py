"""A trajectory handed to a lane of a batch and its results back (C's
struct lanes, templates/c/lanes.jinja): lane_start, put_result and
lanes_finish. Printed by gyrogen.codegen.ir.lanes.LanePrinter (one lane's
values L->v[l]) and, put_result, the C printer."""

from __future__ import annotations

from gyrogen.codegen.integrators import common, driver
from gyrogen.codegen.ir.nodes import (
    At,
    Bin,
    Call,
    Const,
    Decl,
    For,
    Func,
    If,
    Int,
    Num,
    Ref,
    Return,
    S,
    Var,
    and_,
    assign,
    cmp,
    fn,
    inc,
    not_,
    or_,
    real,
)

STRUCT = {"busy": Decl("busy", "int", (), "inout"), "traj": Decl("traj", "size", (), "inout")}
"""What struct lanes holds beyond the methods' state (lanes.jinja declares
them): whether a lane is busy and with which trajectory."""

i, index, st = Var("i"), Var("index"), Var("st")
t0_ = real("t0")
XS, STATS, CODES = Var("xs"), Var("stats"), Var("codes")
OK = common.code("OK")


def stats_kept(state: dict[str, Decl]) -> list[str]:
    """The statistics struct lanes keeps per lane (stats_<field>)."""
    return [d.name.removeprefix("stats.") for d in state.values() if d.name.startswith("stats.")]


def lane_start(state: dict[str, Decl], init: list[S], pairs: bool, events: int) -> Func:
    """state: struct lanes's per-lane values; init: a trajectory's values at
    t0 in its lane (program.Program.init); pairs: k[0] holds f0; events:
    how many (0: none)."""
    t0, code, f, hs = Var("t0"), Var("started"), Var("f"), Var("hs")
    x = Bin("+", XS, index * common.NX)  # the trajectory's row of xs
    args = (Var("order"), Var("rtol_min"), t0, Var("t1"), x, Var("c"), Var("rtol"), Var("atol"),
            Var("h0"), Var("max_steps"), f, Ref("hs"), st)  # fmt: skip
    body: list[S] = [assign(code, fn("ode_start", *args))]
    body += [If(Var("nlogs"), (assign(At("nlogs", (index,)), 0),))] if events else []
    body += [
        If(or_(cmp(code, ">", OK), and_(cmp(code, "==", OK), not_(Var("out")))), (Return(code),)),
        For("i", common.NX, (assign(Var("x")[i], At("xs", (index * common.NX + fn("size", i),))),)),
        If(Var("out"), (assign(driver.BASE, fn("long", index) * Var("ntimes")),
                        *driver.grid_first(driver.BASE))),
    ]  # fmt: skip
    if events:  # the log empty, g at the start (a crossing's first side), no rate seen
        g0 = Var("g0")
        first = (
            assign(Var("ev_old")[i], g0[i]),
            assign(Var("ev_rate")[i], 0.0),
            assign(Var("ev_dold")[i], Num(-1.0)),
        )
        started = (Call("events", (t0, x, Var("c"), g0)), For("i", Int(events), first))
        body.append(If(Var("nlogs"), (
            assign(Var("nlog"), 0),
            assign(driver.LBASE, fn("long", index) * Var("capacity")),
            If(cmp(code, "<=", OK), started),
        )))  # fmt: skip
    body.append(If(cmp(code, ">=", 0), (Return(code),)))
    body += [For("i", common.NX, (assign(Var("k")[0, i], f[i]),))] if pairs else []
    body += [For("i", common.NX, (assign(Var("f0")[i], f[i]),))] if "f0" in state else []
    body += [assign(Var("h"), hs), *init]
    body += driver.lane_stats_start(stats_kept(state), "st")
    body += [assign(Var("busy"), 1), assign(Var("traj"), index), Return(Int(-1))]
    params = (Decl("order", "int"), real("rtol_min"), Decl("index", "size"), t0_, real("t1"),
              Decl("xs", "double", ("n",), "inout"), Decl("c", "double", ("NC",)),
              *common.TOLERANCES, real("h0"), Decl("max_steps", "long"),
              Decl("st", "stats", (), "inout"))  # fmt: skip
    locals_ = (Decl("f", "double", ("NX",), "inout"), Decl("hs", "double", (), "inout", Num(0.0)),
               *((Decl("g0", "double", (events,), "inout"),) if events else ()),
               Decl("started", "int", (), "inout"))  # fmt: skip
    doc = ("A trajectory, index, into lane l, with ode_start's checks: -1 when the lane "
           "took it, else the code it ended with at once (x as given, st set). Over an "
           "output grid (L->out), its rows in out from base = index ntimes, the first one "
           "written unless the start was refused.",)  # fmt: skip
    return checked(Func("lane_start", (Decl("l", "int"), *params), tuple(body), "int", locals_,
                        doc), state)  # fmt: skip


def put_result() -> Func:
    """Trajectory index's statistics and code (x is in place), where wanted."""
    body = (
        If(STATS, (assign(At("stats", (index,)), st[0]),)),
        If(CODES, (assign(At("codes", (index,)), Var("code")),)),
    )
    params = (
        Decl("index", "size"),
        Decl("code", "int"),
        Decl("st", "stats", (), "in"),
        Decl("stats", "stats", ("n",), "out"),
        Decl("codes", "int", ("n",), "out"),
    )
    doc = ("Trajectory index's results: its statistics and code (x is in place).",)
    return Func("put_result", params, body, None, doc=doc)


def lanes_finish(state: dict[str, Decl], events: bool) -> Func:
    """state: struct lanes's per-lane values; events: a lane keeps its log's count."""
    copied = [assign(Var(f"st.{n}"), Var(f"stats.{n}")) for n in stats_kept(state)]
    traj, failed = Var("traj"), Var("failed")
    done: list[S] = [
        Call("stats_start", (Ref("st"), Var("t0"))),
        *copied,
        For("i", common.NX,
            (assign(At("xs", (traj * common.NX + fn("size", i),)), Var("x")[i]),)),
    ]  # fmt: skip
    done += [If(Var("nlogs"), (assign(At("nlogs", (traj,)), Var("nlog")),))] if events else []
    done += [
        Call("put_result", (traj, Var("code"), Ref("st"), STATS, CODES)),
        inc(failed, fn("size", cmp(Var("code"), "!=", OK))),
        assign(Var("busy"), 0),
    ]
    each = If(and_(Var("busy"), cmp(Var("code"), ">=", 0)), tuple(done))
    params = (t0_, Decl("xs", "double", ("n",), "inout"), Decl("stats", "stats", ("n",), "out"),
              Decl("codes", "int", ("n",), "out"))  # fmt: skip
    locals_ = (Decl("failed", "size", (), "inout", Int(0)), Decl("st", "stats", (), "inout"))
    doc = ("The lanes that have a code: their state and statistics out, the lane free.",)
    body = (For("l", Const("LANES"), (each,)), Return(failed))
    return checked(Func("lanes_finish", params, body, "size", locals_, doc), state)


def checked(f: Func, state: dict[str, Decl]) -> Func:
    """f, whose own names are none of struct lanes's (the printer would read
    those as L->name[l])."""
    mine = {d.name for d in (*f.params, *f.locals)}
    theirs = {*state, *STRUCT}
    assert not mine & theirs, f"{f.name}: {sorted(mine & theirs)} are struct lanes's"
    return f


def functions(state: dict[str, Decl], init: list[S], pairs: bool, events: int) -> list[Func]:
    """The handover's functions in the order C defines them."""
    return [lane_start(state, init, pairs, events), put_result(), lanes_finish(state, bool(events))]


__all__ = ["STRUCT", "functions"]
