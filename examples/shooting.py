"""Differential correction with the state transition matrix: the start that
nulls the nutation after T seconds.

The default scene (the paper's gyrostat, every parameter at run time) with
[sensitivities] wrt = ["state"], built in C with the one integrator the
example calls (dop853), so that it builds in seconds. Unknowns: the carrier's transverse rates
u1 and u3 at t = 0; targets: the same rates zero at t = T. Newton's method
on the residual r(z) = (u1(T), u3(T)), its Jacobian the rows and columns u1,
u3 of Phi(T): each iteration one integrate_var. The residual falls quadratically, as printed.

    python examples/shooting.py [--T 2.0]
"""

from __future__ import annotations

import argparse

import numpy as np

from gyrogen import api, scene


def shooting_scene() -> scene.Scene:
    """The default scene with Phi for its state, dop853 in C only."""
    data = scene.load_toml(scene.builtin_text("gyrostat"), "gyrostat (built-in)")
    data.update(targets=["c"], integrators=["dop853"], sensitivities={"wrt": ["state"]})
    return scene.validate(data, "gyrostat with sensitivities")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--T", type=float, default=2.0, help="when the nutation is to be null, s")
    args = ap.parse_args()
    s = shooting_scene()
    model = api.compile(s)
    c = model.setup([s.simulate.parameters[n] for n in s.runtime])
    names = list(s.states)
    unknowns = [names.index("u1"), names.index("u3")]
    targets = [names.index("u1"), names.index("u3")]
    x0 = np.array(s.initial_state())
    print(f"null u1 and u3 at t = {args.T:g} s by choosing u1(0) and u3(0)")
    print(f"{'iteration':>9} {'u1(0)':>22} {'u3(0)':>22} {'|r|':>10}")
    for k in range(8):
        x, phi, _, code = model.integrate_var("dop853", x0, c, 0.0, args.T, rtol=1e-13, atol=1e-13)
        if code != 0:
            raise SystemExit(f"the integration stopped with code {code}")
        r = x[targets]
        norm = float(np.linalg.norm(r))
        print(f"{k:9d} {x0[unknowns[0]]:22.15g} {x0[unknowns[1]]:22.15g} {norm:10.3e}")
        if norm < 1e-13:
            print("converged")
            return
        step = np.linalg.solve(phi[np.ix_(targets, unknowns)], r)
        x0[unknowns] -= step
    raise SystemExit("no convergence in 8 iterations")


if __name__ == "__main__":
    main()
