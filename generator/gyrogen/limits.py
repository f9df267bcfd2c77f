"""Limits on what a user may ask for (command-line options, scene and sweep
files), each where a larger value would exhaust memory or time before
failing; a refusal is one line naming the limit. The interface itself
(names, codes, signatures, thresholds) is abi.py's."""

from __future__ import annotations

MAX_STATES = 10**6
"""`gyrogen verify --states`: random states held at once (0.75 GB at the limit)."""
MAX_PARAMETER_SETS = 10**4
"""`gyrogen verify --params`: random parameter sets, each run over every state."""
MAX_REPEATS = 1000
"""`gyrogen bench-rhs --repeats`: repeats per timing."""
MAX_RHS_CALLS = 10**12
"""`gyrogen simulate --max-nfev`: days of RHS calls; the compiled integrators take it
as a C long, which a larger Python int would overflow."""
MAX_OUTPUT_POINTS = 10**6
"""Output steps of a simulation, t_end/dt (scene [simulate] and `gyrogen
simulate --t-end/--dt`): the trajectory, its quadrature samples and the CSV
text are in memory at once; 10**6 steps of torque_free took 1.3 GB and 17 s."""
MIN_OUTPUT_STEP = 1e-300
"""The shortest output step dt, s (scene [simulate] and `gyrogen simulate
--dt`): the quadrature nodes split each interval into pieces down to 0.11
dt, each a step some integrator must take, and the compiled integrators stop
a step shorter than the smallest normal double (2.2e-308) as an underflow;
below ~1e-307 the samples stop being distinct doubles at all (dt = 5e-324
left a grid of one point)."""
MAX_SCENE_BYTES = 1 << 20
"""Size of a scene file (1 MiB), checked before it is parsed: a real scene is ~2 KB."""
MAX_SWEEP_TRAJECTORIES = 10**10
"""Trajectories in one sweep (grid points times draws): the sample index is a
64-bit integer in the Parquet rows and in the draws' counter, and 10^10 rows
of ~30 doubles are 2.4 TB; a larger sweep is a typo."""
MAX_SWEEP_AXIS = 10**6
"""Values on one grid axis (list, linspace or logspace)."""
MAX_SWEEP_SAMPLES = 10**4
"""Points along each trajectory where the sweep's metrics look (metrics.samples):
each is a restart of the integrator on the whole chunk."""
MAX_SWEEP_CHUNK = 10**6
"""Trajectories per task: a chunk's states and metrics are in memory at once
(10^6 rows of ~40 doubles: 0.3 GB)."""
MAX_SPIN = 1e100
"""`gyrogen linearize --spin` (and api.linearize's spin) and the speeds of
an equilibrium given to linearize, rad/s: the rates
enter the equations squared, times inertias up to 1e50 (a folded value's
bound), which must stay doubles."""
MAX_EVENTS = 64
"""A scene's [[events]]: each is evaluated at every step and searched for zeros."""
MAX_EVENT_TEXT = 1000
"""Characters of an event's expression: a real one is a line (nested deeper,
Python's own parser refuses it first)."""
