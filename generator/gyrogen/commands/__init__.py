"""The `gyrogen` commands: one module per command, named as the command,
each with a `command` (click); cli.py assembles them in this order."""

NAMES = (
    "generate",
    "scenes",
    "new",
    "verify",
    "run",
    "simulate",
    "bench",
    "check",
    "prove",
    "equations",
    "ops",
    "bench_rhs",
    "bench_ensemble",
    "fmu",
    "sweep",
    "linearize",
)
