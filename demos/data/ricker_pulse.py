"""Writes ricker_pulse.csv, the ground acceleration of demos/rocking_block.toml: a Ricker wavelet

    a(t) = A (1 - 2 pi^2 fp^2 (t - t0)^2) exp(-pi^2 fp^2 (t - t0)^2),   0 <= t <= 2 t0,

A = 5.0 m/s^2, fp = 2.0 Hz, t0 = 0.6 s, sampled every dt = 1 ms (1201 rows: t [s], a [m/s^2]). It is the second time
derivative of a Gaussian, so its velocity and displacement return to zero (up to the truncation at t = 0 and 2 t0,
where exp(-pi^2 fp^2 t0^2) = 6.6e-7). A is 2.04 x the uplift threshold g b/h = 9.81 x 0.25 / 1.0 = 2.45 m/s^2 of the
0.25 x 1.0 m block. The values are a choice for the demo (a recorded-style pulse), not a record.
Run: python demos/data/ricker_pulse.py
"""
import math
import os

A, FP, T0, DT = 5.0, 2.0, 0.6, 1e-3


def main(path=os.path.join(os.path.dirname(os.path.abspath(__file__)), "ricker_pulse.csv")):
    n = int(round(2 * T0 / DT))
    with open(path, "w", encoding="utf-8") as f:
        f.write(f"# Ricker wavelet a = A (1 - 2 (pi fp (t - t0))^2) exp(-(pi fp (t - t0))^2), A = {A} m/s^2, "
                f"fp = {FP} Hz, t0 = {T0} s, dt = {DT} s (demos/data/ricker_pulse.py)\n")
        f.write("t,a\n")
        for k in range(n + 1):
            t = k * DT
            x = (math.pi * FP * (t - T0)) ** 2
            f.write(f"{t:.6f},{A * (1 - 2 * x) * math.exp(-x):.12g}\n")


if __name__ == "__main__":
    main()
