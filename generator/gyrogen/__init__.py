"""gyrogen: C and Fortran right-hand sides for a gyrostat, from Kane's equations."""

__version__ = "0.1.0"
