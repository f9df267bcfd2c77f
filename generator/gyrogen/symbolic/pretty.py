"""The equations of motion as people read them: terminal text or LaTeX."""

from __future__ import annotations

import sympy as sm

from gyrogen.symbolic import equations, model

_LATEX_NAMES = {
    "IA11": r"I_{\tilde{A}11}",
    "IA22": r"I_{\tilde{A}22}",
    "IA33": r"I_{\tilde{A}33}",
    "IA13": r"I_{\tilde{A}13}",
    "m_a": "m_a",
    "m_b": "m_b",
    "I11": "I_{11}",
    "I22": "I_{22}",
    "I33": "I_{33}",
    "I13": "I_{13}",
    "l1": "l_1",
    "l3": "l_3",
}


def _by_monomial(expr: sm.Expr, gens: list[sm.Symbol]) -> sm.Expr:
    """expr as a sum over monomials in gens, each coefficient factored."""
    poly = sm.Poly(sm.simplify(expr), *gens)
    terms = [
        sm.factor(c) * sm.Mul(*(g**k for g, k in zip(gens, m, strict=True)))
        for m, c in poly.terms()
    ]
    return sm.Add(*terms)


def _rows(kane: model.KaneEquations) -> list[tuple[sm.Expr, sm.Expr]]:
    """Row r of M u' = F, simplified, with u' written as a symbol."""
    u = list(equations.plain_states()[7:])
    udots = [sm.Symbol(f"{s.name}'", real=True) for s in u]
    mm, f = equations.plain(kane.mass_matrix), equations.plain(kane.forcing)
    rows = []
    for r in range(mm.rows):
        lhs = _by_monomial(sum((mm[r, j] * udots[j] for j in range(mm.cols)), sm.S.Zero), udots)
        rows.append((lhs, _by_monomial(f[r], u)))
    return rows


def _kinematics() -> list[tuple[sm.Expr, sm.Expr]]:
    states = equations.plain_states()
    kin = equations.plain(model.lumped().kinematics)
    return [(sm.Symbol(f"{q.name}'", real=True), kin[i]) for i, q in enumerate(states[:7])]


def _sections() -> list[tuple[str, list[tuple[sm.Expr, sm.Expr]]]]:
    lumped = [(s, v) for s, v in model.lumped_values().items()]
    return [
        ("Kinematic differential equations (both formulations)", _kinematics()),
        ("(a) Separate bodies: M u' = F", _rows(model.separate())),
        ("(b) Lumped carrier + massless rotor: M u' = F", _rows(model.lumped())),
        ("Lumped inertia scalars (J~ = J)", lumped),
    ]


def text() -> str:
    out = []
    for title, rows in _sections():
        out += [title, "-" * len(title)]
        for lhs, rhs in rows:
            out.append(f"  {sm.sstr(lhs)} = {sm.sstr(rhs)}")
        out.append("")
    return "\n".join(out)


def latex() -> str:
    names = {sm.Symbol(k, real=True): v for k, v in _LATEX_NAMES.items()}
    out = []
    for title, rows in _sections():
        out += [f"% {title}", r"\begin{align}"]
        body = [
            f"  {sm.latex(lhs, symbol_names=names)} &= {sm.latex(rhs, symbol_names=names)}"
            for lhs, rhs in rows
        ]
        out += [" \\\\\n".join(body), r"\end{align}", ""]
    return "\n".join(out)
