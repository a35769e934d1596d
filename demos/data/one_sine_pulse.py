"""Writes one_sine_pulse.csv, the ground acceleration of demos/rocking_block.toml: a one-sine pulse

    a(t) = A sin(2 pi t / T_p),  0 <= t <= T_p,   A = 4.0 m/s^2, T_p = 0.5 s,

sampled every dt = 1 ms (501 rows: t [s], a [m/s^2]). A is 1.63 x the uplift threshold g b/h = 9.81 x 0.25 / 1.0
= 2.45 m/s^2 of the 0.25 x 1.0 m block. The values are a choice for the demo (a recorded-style pulse), not a record.
Run: python demos/data/one_sine_pulse.py
"""
import math
import os

A, TP, DT = 4.0, 0.5, 1e-3


def main(path=os.path.join(os.path.dirname(os.path.abspath(__file__)), "one_sine_pulse.csv")):
    n = int(round(TP / DT))
    with open(path, "w", encoding="utf-8") as f:
        f.write(f"# one-sine pulse a = A sin(2 pi t / Tp), A = {A} m/s^2, Tp = {TP} s, dt = {DT} s "
                "(demos/data/one_sine_pulse.py)\n")
        f.write("t,a\n")
        for k in range(n + 1):
            t = k * DT
            f.write(f"{t:.6f},{A * math.sin(2 * math.pi * t / TP):.12g}\n")


if __name__ == "__main__":
    main()
