#!/usr/bin/python3
"""How far any linear model gets on a record: ARX and output-error fits of increasing order.

What it does
------------
For a record with one input or several (a common denominator, one numerator
per input) split into an estimation part (the first FRACTION)
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
    scripts/study/linear_bound.py RECORD.csv --u u1,u2 --y y5 --orders 8,16   # two inputs

Needs numpy and scipy (Debian's python3-numpy, python3-scipy).
"""
import argparse

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import lfilter


def fit_percent(y, y_sim):
    return 100.0 * (1.0 - np.linalg.norm(y - y_sim) / np.linalg.norm(y - y.mean()))


def arx(y, us, n, end):
    """A (n), one B (n) per input in us, and the constant."""
    rows = [np.concatenate([-y[k - n:k][::-1]] + [u[k - n + 1:k + 1][::-1] for u in us] + [[1.0]])
            for k in range(n, end)]
    theta = np.linalg.lstsq(np.array(rows), y[n:end], rcond=None)[0]
    return theta[:n], [theta[n * (j + 1):n * (j + 2)] for j in range(len(us))], theta[-1]


def simulate(a, bs, offset, us):
    return sum(lfilter(b, np.r_[1.0, a], u) for b, u in zip(bs, us)) + offset


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("record")
    ap.add_argument("--u", default="u", help="input column, or several comma-separated")
    ap.add_argument("--y", default="y")
    ap.add_argument("--fraction", type=float, default=0.7)
    ap.add_argument("--orders", default="2,4,6,8,10")
    args = ap.parse_args()
    d = np.genfromtxt(args.record, delimiter=",", names=True)
    us, y = [d[c] for c in args.u.split(",")], d[args.y]
    m = len(us)
    ne = int(round(args.fraction * len(y)))
    print("%d samples: %d to estimate, %d to validate" % (len(y), ne, len(y) - ne))
    print("%5s %14s %14s %14s %14s %8s" % ("order", "ARX est. %", "ARX val. %", "OE est. %", "OE val. %", "stable"))
    for n in (int(o) for o in args.orders.split(",")):
        a, bs, c = arx(y, us, n, ne)
        y_arx = simulate(a, bs, c / (1.0 + a.sum()), us)

        def unpack(p):
            return p[:n], [p[n * (j + 1):n * (j + 2)] for j in range(m)], p[-1]

        def residual(p):
            return (simulate(*unpack(p), us) - y)[:ne]

        p = least_squares(residual, np.concatenate([a] + bs + [[c / (1.0 + a.sum())]]), method="lm",
                          max_nfev=5000).x
        y_oe = simulate(*unpack(p), us)
        stable = bool(np.all(np.abs(np.roots(np.r_[1.0, p[:n]])) < 1.0))
        print("%5d %14.2f %14.2f %14.2f %14.2f %8s" % (n, fit_percent(y[:ne], y_arx[:ne]), fit_percent(y[ne:], y_arx[ne:]),
                                                     fit_percent(y[:ne], y_oe[:ne]), fit_percent(y[ne:], y_oe[ne:]),
                                                     "yes" if stable else "no"))


if __name__ == "__main__":
    main()
