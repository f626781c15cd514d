#!/usr/bin/python3
"""How far any linear model gets on a record: ARX and output-error fits of increasing order.

What it does
------------
For a single-input record split into an estimation part (the first FRACTION)
and a validation part (the rest), fits ARX(n, n) with a constant by least
squares on the estimation part, then refines it to output error (simulation
error, Levenberg-Marquardt from the ARX start), for n = 2, 4, ..., and prints
each model's fit on both parts: fit % = 100 (1 - ||y - y_sim|| / ||y - mean(y)||),
the model simulated from u over the whole record (the validation part starts
from the state the estimation part leaves). An order picked on the validation
part flatters that part; the output-error column says what fitting the
estimation part buys on the validation part. A modal model of `diagnose`
compares with the output-error column.

How to run it
-------------
    scripts/study/linear_bound.py RECORD.csv [--u u] [--y y] [--fraction 0.7] [--orders 2,4,6,8,10]

Needs numpy and scipy (Debian's python3-numpy, python3-scipy).
"""
import argparse

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import lfilter


def fit_percent(y, y_sim):
    return 100.0 * (1.0 - np.linalg.norm(y - y_sim) / np.linalg.norm(y - y.mean()))


def arx(y, u, n, end):
    rows = [np.r_[-y[k - n:k][::-1], u[k - n + 1:k + 1][::-1], 1.0] for k in range(n, end)]
    theta = np.linalg.lstsq(np.array(rows), y[n:end], rcond=None)[0]
    return theta[:n], theta[n:2 * n], theta[-1]


def simulate(a, b, offset, u):
    return lfilter(b, np.r_[1.0, a], u) + offset


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("record")
    ap.add_argument("--u", default="u")
    ap.add_argument("--y", default="y")
    ap.add_argument("--fraction", type=float, default=0.7)
    ap.add_argument("--orders", default="2,4,6,8,10")
    args = ap.parse_args()
    d = np.genfromtxt(args.record, delimiter=",", names=True)
    u, y = d[args.u], d[args.y]
    ne = int(round(args.fraction * len(y)))
    print("%d samples: %d to estimate, %d to validate" % (len(y), ne, len(y) - ne))
    print("%5s %14s %14s %14s %14s %8s" % ("order", "ARX est. %", "ARX val. %", "OE est. %", "OE val. %", "stable"))
    for n in (int(o) for o in args.orders.split(",")):
        a, b, c = arx(y, u, n, ne)
        y_arx = simulate(a, b, c / (1.0 + a.sum()), u)

        def residual(p):
            return (simulate(p[:n], p[n:2 * n], p[-1], u) - y)[:ne]

        p = least_squares(residual, np.r_[a, b, c / (1.0 + a.sum())], method="lm", max_nfev=5000).x
        y_oe = simulate(p[:n], p[n:2 * n], p[-1], u)
        stable = bool(np.all(np.abs(np.roots(np.r_[1.0, p[:n]])) < 1.0))
        print("%5d %14.2f %14.2f %14.2f %14.2f %8s" % (n, fit_percent(y[:ne], y_arx[:ne]), fit_percent(y[ne:], y_arx[ne:]),
                                                     fit_percent(y[:ne], y_oe[:ne]), fit_percent(y[ne:], y_oe[ne:]),
                                                     "yes" if stable else "no"))


if __name__ == "__main__":
    main()
