"""Checks shared by the 2D and 3D interface tables (detection_2d.InterfaceTable, detection_3d.InterfaceTable):
one entry per interface in every per-interface array, joint thickness g0 >= 0, alert distance > 0, and candidate
positions strictly inside (0, 1) with at least one per interface placed by positions (placement 0)."""
from __future__ import annotations

import numpy as np

from ..errors import InputError


def check_lengths(table, names, ni: int) -> None:
    for name in names:
        if len(getattr(table, name)) != ni:
            raise InputError(f"interface table: {name} has {len(getattr(table, name))} entries, expected {ni}")


def check_g0_alert(g0, alert) -> None:
    if np.any(~np.isfinite(g0)) or np.any(g0 < 0):
        raise InputError("interfaces.g0: expected joint thickness >= 0 [m]")
    if np.any(~np.isfinite(alert)) or np.any(alert <= 0):
        raise InputError("interfaces.alert: expected alert distance > 0 [m]")


def check_positions(positions, placement, ni: int) -> None:
    p = np.asarray(positions)
    if p.ndim != 2 or p.shape[0] != ni:
        raise InputError("interfaces.positions: expected one row per interface")
    used = p >= 0
    if np.any((p[used] <= 0) | (p[used] >= 1)):
        raise InputError("interfaces.positions: expected relative positions strictly between 0 and 1")
    if np.any((placement == 0) & ~used.any(axis=1)):
        raise InputError("interfaces.positions: expected at least one position")
