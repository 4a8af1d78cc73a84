#!/usr/bin/env python3
"""A plain scipy self-calibration of a campaign CSV: the baseline `rpkm bench calibration`
measures rpkm against, written from the spec (shared/spec/scissors-kinematics.md), not from
rpkm's code.

The rows: every `self` pose (q2, q3 following) gives two residuals, the follower positions the
model predicts from (q1, q4) minus the recorded ones: fgm of the non-redundant subsystem (rods 1,
4, 5; Gauss-Newton on x, y, psi, all poses at once), then the inverse model of rods 2 and 3 with
the spec's assembly mode (carrier 2 above its platform joint, carrier 3 below). The unknowns:
the 29 parameters of model 29, each held near nominal by its manufacturing tolerance
(0.1 mm, 1 mrad) as pseudo-rows, like `rpkm calibrate --params map`. Rows weighted by the
encoder noise (0.2 um, the spec's default). scipy.optimize.least_squares with its defaults (trf,
2-point Jacobian), as a user would write it.

Prints `seconds S` (the fit alone, not reading the file), `nfev N`, and with --json FILE the
identified parameters by spec name.

Usage: scipy_calibration.py CAMPAIGN.csv [--json OUT.json]
"""

import csv
import json
import sys
import time

import numpy as np
from scipy.optimize import least_squares

# spec table, index 1..29 -> (name, nominal)
NAMES = [
    "l1", "l4", "l5", "xa1r", "xa4r", "xa5r", "ya1r", "ya4r", "ya5r", "xb1r", "xb4r",
    "xb5r", "yb1r", "yb4r", "yb5r", "d2", "gamma2", "l2", "l3", "xa2r", "xa3r", "ya2r",
    "ya3r", "xb2r", "xb3r", "yb2r", "yb3r", "d1", "gamma1",
]
NOMINAL = [
    950, 950, 950, 520, 520, 520, 280, -280, 280, -310, -310, -310, 80, -80, 480, 1460, 0,
    950, 950, -520, -520, 280, -280, 310, 310, 80, -80, -1460, 0,
]
IDX = {n: i for i, n in enumerate(NAMES)}
ENCODER_MM = 0.0002
TOL_MM, TOL_RAD = 0.1, 1e-3


def rod(i):
    """Parameter indexes (l, xa, ya, xb, yb) and guide (d, gamma) of rod i (1..5)."""
    s = f"{i}r"
    guide = ("d2", "gamma2") if i in (1, 4, 5) else ("d1", "gamma1")
    return [IDX[n] for n in (f"l{i}", f"xa{s}", f"ya{s}", f"xb{s}", f"yb{s}", *guide)]


RODS = {i: rod(i) for i in range(1, 6)}


def joints(p, r, x, y, psi, q):
    """A - B of rod r for arrays of poses."""
    l, xa, ya, xb, yb, d, g = (p[k] for k in RODS[r])
    c, s = np.cos(psi), np.sin(psi)
    ax, ay = x + c * xa - s * ya, y + s * xa + c * ya
    e = (-np.sin(g), np.cos(g))
    n = (np.cos(g), np.sin(g))
    bx = d + xb * n[0] + (q + yb) * e[0]
    by = xb * n[1] + (q + yb) * e[1]
    return ax - bx, ay - by, l


def fgm(p, q1, q4, x, y, psi):
    """Rods 1, 4, 5 closed for (q1, q4): Gauss-Newton on (x, y, psi), every pose at once,
    numeric 3x3 Jacobians (what a plain script does)."""
    def f(x, y, psi):
        out = []
        for r, q in ((1, q1), (4, q4), (5, q4)):
            dx, dy, l = joints(p, r, x, y, psi, q)
            out.append(dx * dx + dy * dy - l * l)
        return np.stack(out, axis=-1)

    for _ in range(30):
        e = f(x, y, psi)
        if np.max(np.abs(e)) < 1e-9:
            break
        h = 1e-6
        jac = np.stack(
            [(f(x + h, y, psi) - e) / h, (f(x, y + h, psi) - e) / h, (f(x, y, psi + h) - e) / h],
            axis=-1,
        )
        step = np.linalg.solve(jac, -e[..., None])[..., 0]
        x, y, psi = x + step[:, 0], y + step[:, 1], psi + step[:, 2]
    return x, y, psi


def igm_rod(p, r, x, y, psi, above):
    """q of rod r's carrier for the platform pose: |A - B(q)| = l, the root on the assembly
    mode's side (carrier above its joint, or below)."""
    l, xa, ya, xb, yb, d, g = (p[k] for k in RODS[r])
    c, s = np.cos(psi), np.sin(psi)
    ax, ay = x + c * xa - s * ya, y + s * xa + c * ya
    e = np.array([-np.sin(g), np.cos(g)])
    n = np.array([np.cos(g), np.sin(g)])
    # B(q) = o + t e with o = (d, 0) + xb n + yb e, t = q + yb... solve |o + t e - A| = l
    ox, oy = d + xb * n[0] + yb * e[0], xb * n[1] + yb * e[1]
    wx, wy = ax - ox, ay - oy
    along = wx * e[0] + wy * e[1]
    across2 = wx * wx + wy * wy - along * along
    root = np.sqrt(np.maximum(l * l - across2, 0.0))
    return along + root if above else along - root


def read(path):
    with open(path, newline="") as fh:
        rows = [r for r in csv.DictReader(l for l in fh if not l.startswith("#"))]
    rows = [r for r in rows if r["instrument"] == "self"]
    q = np.array([[float(r[f"q{k}"]) for k in range(1, 5)] for r in rows])
    return q


def main():
    args = sys.argv[1:]
    if not args:
        sys.exit(__doc__)
    out_json = None
    if "--json" in args:
        k = args.index("--json")
        out_json = args[k + 1]
        del args[k : k + 2]
    q = read(args[0])
    nominal = np.array(NOMINAL, dtype=float)
    tol = np.array([TOL_RAD if n.startswith("gamma") else TOL_MM for n in NAMES])
    start = {"x": np.zeros(len(q)), "y": None, "psi": np.zeros(len(q))}
    # a start pose for every row: the nominal machine's fgm from a mid-workspace guess
    x0, y0, psi0 = fgm(nominal, q[:, 0], q[:, 3], np.zeros(len(q)), np.full(len(q), 1700.0), np.zeros(len(q)))
    start.update(x=x0, y=y0, psi=psi0)

    def residuals(p):
        x, y, psi = fgm(p, q[:, 0], q[:, 3], start["x"], start["y"], start["psi"])
        q2 = igm_rod(p, 2, x, y, psi, above=True)
        q3 = igm_rod(p, 3, x, y, psi, above=False)
        rows = np.concatenate([(q2 - q[:, 1]), (q3 - q[:, 2])]) / ENCODER_MM
        return np.concatenate([rows, (p - nominal) / tol])

    t0 = time.perf_counter()
    fit = least_squares(residuals, nominal, x_scale=tol)
    seconds = time.perf_counter() - t0
    print(f"seconds {seconds:.4f}")
    print(f"nfev {fit.nfev}")
    print(f"poses {len(q)}")
    if out_json:
        with open(out_json, "w") as fh:
            json.dump({n: float(v) for n, v in zip(NAMES, fit.x)}, fh, indent=1)


if __name__ == "__main__":
    main()
