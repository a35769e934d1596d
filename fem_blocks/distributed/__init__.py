"""Distributed time stepper pieces on MPI and PETSc (docs/scaling.md)."""
