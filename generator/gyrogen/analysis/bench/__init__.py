"""The benchmarks: bench-rhs, bench (work-precision), bench-ensemble."""

RHS_JSON = "bench.json"
"""What `gyrogen bench-rhs --out DIR` writes into DIR (its help reads it here:
the command imports this package's light __init__ only)."""
