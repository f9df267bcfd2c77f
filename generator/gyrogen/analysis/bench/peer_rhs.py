"""gyrogen's optimized rhs block on another library's symbols: the peers
that take a system as expressions (CasADi's SX in workprec_peers, heyoka's
in heyoka_peer) get the same arithmetic as the generated code."""

from __future__ import annotations

from typing import Any


def rhs_values(unit: Any, x: Any, c: Any, funcs: dict[str, Any]) -> list[Any]:
    """gyrogen's optimized rhs block, statement by statement, on another
    library's symbols (CasADi's SX, heyoka's expressions): x and c indexable
    by state and constant, funcs its sin, cos and sqrt (the same arithmetic
    as the generated code)."""
    import sympy as sm

    from gyrogen.symbolic.hoist import constants

    env: dict[Any, Any] = {s: x[i] for i, s in enumerate(unit.states)}
    env.update({k: c[i] for i, k in enumerate(constants(unit.nc))})
    modules = [funcs, "math"]

    def value(expr: sm.Expr) -> Any:
        args = sorted(expr.free_symbols, key=str)
        return sm.lambdify(args, expr, modules=modules)(*(env[a] for a in args))

    block = unit.optimized.rhs
    for a in block.temporaries:
        env[a.lhs] = value(a.rhs)
    return [value(e) for e in block.outputs]
